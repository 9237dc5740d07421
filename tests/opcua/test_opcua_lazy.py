"""The lazy address space (``_lazy``): each drive node it makes is the node asyncua makes.

And it makes only what a client asks for, keeps what a monitored item watches, and drops
the rest past its bound.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import pytest
from asyncua import ua
from asyncua.server.address_space import NodeData
from waiting import wait_for

from sj300_async.gateway.opcua._lazy import LazyNodes, make_shape
from sj300_async.gateway.opcua._model import build_drive
from sj300_async.gateway.opcua._server import OpcuaServer
from sj300_async.gateway.opcua._space import SpaceBuilder
from sj300_async.gateway.opcua._speedups import ENABLED

from .conftest import NAMESPACE, PASSWORD, USER, Pair, connected, opcua_gateway, opcua_toml

pytestmark = pytest.mark.skipif(
    not ENABLED, reason="the speed patches are off: every node is made at start"
)

#: Two lines of two protocols; drives of one line with and without control and grants,
#: a parameter granted to one drive only: five shapes.
_LINES = textwrap.dedent(
    """
    [[lines.writes]]
    nodes = "3"
    parameters = ["A004"]
    [[lines]]
    name = "pumps"
    url = "sim://?protocol=fr700&nodes=5-6"
    protocol = "fr700"
    nodes = "5-6"
    interval_s = 0.1
    [[lines.writes]]
    nodes = "6"
    control = true
    """
)


def _table(server: OpcuaServer) -> LazyNodes:
    table = server.lazy_nodes
    assert table is not None
    return table


def _attributes(node: NodeData) -> dict[Any, Any]:
    """Each attribute's value and status (the timestamps are each node's own), the value's
    read callback and setter as present or not."""
    out: dict[Any, Any] = {}
    for attribute, value in node.attributes.items():
        data = value.value
        shown = None if data is None else (data.Value, data.StatusCode)
        out[attribute] = (shown, value.value_callback is not None, value.value_setter is not None)
    return out


def _references(node: NodeData) -> list[Any]:
    return [
        (r.ReferenceTypeId, r.IsForward, r.NodeId, r.BrowseName, r.DisplayName, r.NodeClass,
         r.TypeDefinition)
        for r in node.references
    ]  # fmt: skip


async def test_every_node_made_is_the_node_asyncua_makes_for_that_drive(tmp_path: Path) -> None:
    async with opcua_gateway(opcua_toml(tmp_path, line_extra="", users=True) + _LINES) as (
        gateway,
        server,
    ):
        table = _table(server)
        space = server.address_space
        assert space is not None
        namespace = server.namespace
        checked = 0
        for line in gateway.lines:
            line_id = ua.NodeId(line.config.name, namespace)
            for drive in line.drives.values():
                # asyncua's own nodes of this drive, made apart from the served space.
                builder = SpaceBuilder(namespace)
                control = line.config.control_allowed(drive.node)
                nodes = build_drive(builder, line_id, line.config.name, drive, control=control)
                own = make_shape(space, builder.items, str(nodes.node.Identifier), line_id)
                for relative, expected in own.nodes.items():
                    made = table.get(expected.nodeid)
                    assert made is not None, expected.nodeid
                    assert made.nodeid == expected.nodeid
                    got, want = _attributes(made), _attributes(expected)
                    value = ua.AttributeIds.Value
                    if relative in {b.name for b in nodes.bindings}:
                        # The served one reads its binding (the prototype holds no value).
                        assert got.pop(value)[1:] == (True, True), relative
                        want.pop(value)
                    assert (relative, got) == (relative, want)
                    assert (relative, _references(made)) == (relative, _references(expected))
                    is_method = expected.attributes[ua.AttributeIds.NodeClass].value
                    assert is_method is not None
                    if is_method.Value.Value == ua.NodeClass.Method:
                        assert made.call is not None, relative
                    checked += 1
        assert checked == server.node_count - _eager(server)
        # The line objects list their drives as asyncua lists a component.
        for line in gateway.lines:
            listed = space[ua.NodeId(line.config.name, namespace)].references
            drives = [r.BrowseName.Name for r in listed if r.BrowseName.Name[5:].isdigit()]
            assert drives == [f"Drive{node}" for node in line.drives]


def _eager(server: OpcuaServer) -> int:
    """The nodes of the gateway's namespace made at start (the Lines folder, the lines;
    not the trip event's type)."""
    space = server.address_space
    assert space is not None
    table = _table(server)
    made = sum(1 for node in table._nodes if node.NamespaceIndex == server.namespace)
    return made - table.kept - server.event_type_nodes


async def test_a_browse_of_the_lines_makes_no_drive_node(tmp_path: Path, client_pair: Pair) -> None:
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (_, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as client,
    ):
        ns = await client.get_namespace_index(NAMESPACE)
        line = client.get_node(ua.NodeId("hall", ns))
        # A browse answers from the line's references: no drive node is looked at.
        names = {d.BrowseName.Name for d in await line.get_children_descriptions()}
        assert {"Drive1", "Drive2", "Drive3", "Drive4"} <= names
        assert _table(server).made == 0
        # A drive's variable read: that node is made, and only it.
        value = await client.get_node(
            ua.NodeId("hall/Drive1/Monitoring/ConverterOutputFrequency", ns)
        ).read_attribute(ua.AttributeIds.Value, raise_on_bad_status=False)
        assert value.StatusCode is not None
        assert _table(server).made == 1


@pytest.mark.parametrize(
    "identifier",
    [
        "hall/Drive1/",
        "hall/Drive9/Online",
        "hall/Drive1/Monitoring/Nothing",
        "hall//Online",
        "hall/Drive1//Online",
        "nowhere/Drive1/Online",
        "hall/drive1/Online",
        "",
    ],
)
async def test_an_id_of_no_node_makes_nothing(
    tmp_path: Path, client_pair: Pair, identifier: str
) -> None:
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (_, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as client,
    ):
        ns = await client.get_namespace_index(NAMESPACE)
        value = await client.get_node(ua.NodeId(identifier, ns)).read_attribute(
            ua.AttributeIds.Value, raise_on_bad_status=False
        )
        assert value.StatusCode is not None
        assert value.StatusCode.name == "BadNodeIdUnknown"
        assert _table(server).made == 0


async def test_made_nodes_are_bounded_but_a_watched_one_stays_and_is_notified(
    tmp_path: Path, client_pair: Pair
) -> None:
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (_, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as client,
    ):
        table = _table(server)
        ns = await client.get_namespace_index(NAMESPACE)
        # Drive 2 runs: its output frequency changes at every sample.
        drive = client.get_node(ua.NodeId("hall/Drive2", ns))
        await drive.call_method(ua.NodeId("hall/Drive2/TakeControl", ns))
        hz = ua.Variant(50.0, ua.VariantType.Double)
        await drive.call_method(ua.NodeId("hall/Drive2/SetFrequency", ns), hz)
        await drive.call_method(ua.NodeId("hall/Drive2/Run", ns), "forward")
        table.keep = 4
        watched = ua.NodeId("hall/Drive2/Monitoring/ConverterOutputFrequency", ns)
        seen: list[Any] = []

        class Handler:
            def datachange_notification(self, node: Any, value: Any, data: Any) -> None:
                seen.append(value)

        subscription = await client.create_subscription(100, Handler())
        await subscription.subscribe_data_change(client.get_node(watched))
        everything = [
            ua.NodeId(f"hall/Drive{node}/{path}", ns)
            for node in range(1, 5)
            for path in ("Online", "Monitoring/State", "Logbook/TripCount", "Parameters/A004")
        ]
        for node in everything:  # read one by one: each made, the oldest dropped past 4
            assert (
                await client.get_node(node).read_attribute(
                    ua.AttributeIds.Value, raise_on_bad_status=False
                )
            ).StatusCode is not None
            assert table.kept <= table.keep + 1  # the watched one beside the bound
        assert table.dropped >= len(everything) - table.keep
        space = server.address_space
        assert space is not None
        assert watched in table._nodes  # never dropped while watched
        count = len(seen)
        await wait_for(lambda: len(set(seen[count:])) > 2, "notifications go on", timeout=10)
        await subscription.delete()
        # Unwatched now: it goes with the next nodes made.
        for node in everything[:8]:
            await client.get_node(node).read_attribute(
                ua.AttributeIds.Value, raise_on_bad_status=False
            )
        await wait_for(lambda: watched not in table._nodes, "the unwatched node dropped")
