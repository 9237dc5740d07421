"""The lazy address space (``_lazy``) under an adversary's requests: probes of issue 44's table.

A client with no credentials (an anonymous session on the None endpoint,
which :func:`opcua_toml` offers) names drive nodes that exist and ids that
name nothing, in every service that looks a node up; it pins nodes with
monitored items and leaves abruptly; it writes to every attribute of a made
node. What must hold:

- memory stays bounded: the nodes held are at most ``keep`` plus those a
  monitored item watches, and an id that names no node makes nothing;
- a made node shares its prototype's attribute values with every drive of
  its shape, so no write path may change one (a change would show on every
  drive of the shape);
- a node dropped and made again is the same node: same references, same
  values, its method still bound.

The loop-lag figures of a flood (one read of 30,000 drive nodes) are in the
report of this probe, not asserted here.
"""

from __future__ import annotations

import asyncio
import contextlib
from pathlib import Path
from typing import Any

import pytest
from asyncua import Client, ua
from asyncua.ua.uaerrors import UaStatusCodeError
from waiting import wait_for

from sj300_async.gateway.opcua._lazy import LazyNodes
from sj300_async.gateway.opcua._operations import MAX_OPERATIONS
from sj300_async.gateway.opcua._server import OpcuaServer
from sj300_async.gateway.opcua._speedups import ENABLED

from .conftest import NAMESPACE, PASSWORD, USER, Pair, connected, opcua_gateway, opcua_toml, polled

pytestmark = pytest.mark.skipif(
    not ENABLED, reason="the speed patches are off: every node is made at start"
)

#: Every attribute an OPC UA node may have (Part 3, 5.9; asyncua's ids 1-27).
_ATTRIBUTES = [ua.AttributeIds(number) for number in range(1, 28)]


def _table(server: OpcuaServer) -> LazyNodes:
    table = server.lazy_nodes
    assert table is not None
    return table


def _relatives(table: LazyNodes) -> list[str]:
    """Every path below a drive object of hall's first shape ("" for the object)."""
    shape = table._drives[("hall", "Drive1")].shape
    return sorted(shape.nodes)


def _drive_ids(table: LazyNodes, ns: int, drives: range = range(1, 5)) -> list[ua.NodeId]:
    """Every node id of hall's drives *drives*."""
    ids = []
    for number in drives:
        shape = table._drives[("hall", f"Drive{number}")].shape
        for relative in sorted(shape.nodes):
            path = f"hall/Drive{number}" + (f"/{relative}" if relative else "")
            ids.append(ua.NodeId(path, ns))
    return ids


def _watched_nodes(table: LazyNodes) -> int:
    """Drive nodes held now that a monitored item watches (any attribute)."""
    held = list(table._made) + list(table._kept)
    return sum(
        1
        for key in held
        if any(value.datachange_callbacks for value in table._nodes[key].attributes.values())
    )


def _bounded(table: LazyNodes, watched: int) -> None:
    """At most keep nodes unwatched, beside *watched* (the most nodes watched at once since
    the last check: a node no longer watched is looked at again, two per node made)."""
    assert len(table._made) <= table.keep, (len(table._made), table.keep)
    assert table.kept <= table.keep + watched, (table.kept, table.keep, watched)


def _untracked(table: LazyNodes) -> list[ua.NodeId]:
    """Drive nodes in asyncua's table that the lazy table does not account for (never
    dropped: a leak)."""
    held = set(table._made) | set(table._kept)
    out = []
    for key in table._nodes:
        identifier = key.Identifier
        if key.NamespaceIndex != table._namespace or not isinstance(identifier, str):
            continue
        line, _, rest = identifier.partition("/")
        if (line, rest.partition("/")[0]) in table._drives and key not in held:
            out.append(key)
    return out


def _bad_ids(ns: int) -> list[ua.NodeId]:
    """Ids in the gateway's namespace and elsewhere that name no node (malformed paths,
    other identifier types, a string near the request limit)."""
    strings = [
        "hall/Drive1/Online/",
        "hall/Drive1//Online",
        "hall//Drive1/Online",
        "/hall/Drive1/Online",
        "hall/Drive1/Monitoring/",
        "hall/Drive1/Monitoring//State",
        "hall/Drive1/Online/Online",
        "hall/Drive01/Online",
        "hall/Drive1 /Online",
        "hall/Drive1/online",
        "hall/Drive\u0661/Online",  # an Arabic-Indic one
        "hall/Drive1/\u00d6nline",
        "hall/Drive1/Onl\u0131ne",
        "hall/Drive\U0001f600/Online",
        "hall/Drive1/Online\x00",
        "hall\x00/Drive1/Online",
        "hall/Drive1/" + "Monitoring/" * 200,
        "hall/Drive99999999999999999999/Online",
        "hall/Drive-1/Online",
        "hall/Drive5/Online",
        "hall/Drive3/Run",  # a node of drive 1's shape that drive 3's has not (no control)
        "hall/Drive3/TakeControl/OutputArguments",
        "hall/Drive1/" + "x" * 100_000,
    ]
    ids = [ua.NodeId(text, ns) for text in strings]
    ids += [
        ua.NodeId(1, ns),
        ua.NodeId(4_294_967_295, ns),
        ua.NodeId(ua.Guid("72962b91-fa75-4ae6-8d28-b404dc7daf63"), ns),
        ua.NodeId(b"hall/Drive1/Online", ns, ua.NodeIdType.ByteString),
    ]
    # The same path in every other namespace the server has, and one it has not.
    ids += [ua.NodeId("hall/Drive1/Online", other) for other in (0, 1, 2, 3, 65535) if other != ns]
    return ids


async def _every_lookup(client: Client, ids: list[ua.NodeId]) -> list[str]:
    """Read (a value, a name), browse, translate paths from, register, history-read and
    watch each of *ids*: the statuses answered (a whole request's refusal among them)."""
    uaclient = client.uaclient
    own = await client.get_namespace_index(NAMESPACE)
    statuses: list[str] = []

    async def answered(coroutine: Any) -> Any:
        try:
            return await coroutine
        except UaStatusCodeError as exc:
            statuses.append(ua.StatusCode(exc.code).name)
            return None

    read = ua.ReadParameters()
    read.NodesToRead = [
        ua.ReadValueId(NodeId=node, AttributeId=attribute)
        for node in ids
        for attribute in (ua.AttributeIds.Value, ua.AttributeIds.BrowseName)
    ]
    values = await answered(uaclient.read(read))
    statuses += [v.StatusCode.name for v in values or ()]
    browse = _browse_both(ids)
    browsed = await answered(uaclient.browse(browse))
    statuses += [r.StatusCode.name for r in browsed or ()]
    paths = [
        ua.BrowsePath(
            StartingNode=node,
            RelativePath=ua.RelativePath(
                Elements=[
                    ua.RelativePathElement(
                        ReferenceTypeId=ua.NodeId(ua.ObjectIds.HierarchicalReferences),
                        IncludeSubtypes=True,
                        TargetName=ua.QualifiedName(name, own),
                    )
                ]
            ),
        )
        for node in ids
        for name in ("Online", "Monitoring", "")
    ]
    translated = await answered(uaclient.translate_browsepaths_to_nodeids(paths))
    statuses += [r.StatusCode.name for r in translated or ()]
    registered = await answered(uaclient.register_nodes(ids))
    if registered:
        await answered(uaclient.unregister_nodes(registered))
    history = ua.HistoryReadParameters()
    history.HistoryReadDetails = ua.ReadRawModifiedDetails(
        IsReadModified=False, NumValuesPerNode=10, ReturnBounds=False
    )
    history.TimestampsToReturn = ua.TimestampsToReturn.Both
    history.NodesToRead = [ua.HistoryReadValueId(NodeId=node) for node in ids]
    # asyncua answers Good, no values, for a node it does not historize, whether it exists
    # or not (the gateway historizes none): only that the request is served is looked at.
    await answered(uaclient.history_read(history))
    subscription = await client.create_subscription(100, None)
    try:
        for attribute in (ua.AttributeIds.Value, ua.AttributeIds.DisplayName):
            handles = await answered(
                subscription.subscribe_data_change(
                    [client.get_node(node) for node in ids], attr=attribute
                )
            )
            for handle in handles or ():
                if isinstance(handle, int):
                    await answered(subscription.unsubscribe(handle))
                else:
                    statuses.append(handle.name)
    finally:
        await subscription.delete()
    return statuses


async def test_no_lookup_of_an_id_that_names_no_node_makes_one(tmp_path: Path) -> None:
    """Anonymous, unsecured: malformed paths, other id types and namespaces, in every service
    that looks a node up, make nothing, and each is answered."""
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (_, server),
        connected(server.url) as client,
    ):
        table = _table(server)
        ns = await client.get_namespace_index(NAMESPACE)
        assert ns == server.namespace
        before = len(table._nodes)
        statuses = await _every_lookup(client, _bad_ids(ns))
        assert table.made == 0
        assert table.kept == 0
        assert len(table._nodes) == before
        assert "BadNodeIdUnknown" in statuses
        assert all(status.startswith("Bad") for status in statuses), set(statuses)
        # One id near the request's 4 MiB bound, read and browsed.
        huge = ua.NodeId("hall/Drive1/" + "Online" * 690_000, ns)
        read = ua.ReadParameters()
        read.NodesToRead = [ua.ReadValueId(NodeId=huge, AttributeId=ua.AttributeIds.Value)]
        (value,) = await client.uaclient.read(read)
        assert value.StatusCode.name == "BadNodeIdUnknown"
        assert table.made == 0
        assert len(table._nodes) == before


def _eight_drives(directory: Path) -> str:
    """:func:`opcua_toml` with drives 1-8 on hall (1-2 granted control, as there)."""
    text = opcua_toml(directory, url="sim://?nodes=1-8")
    return text.replace('nodes = "1-4"', 'nodes = "1-8"')


async def test_a_flood_of_lookups_of_existing_nodes_holds_keep_and_the_watched(
    tmp_path: Path,
) -> None:
    """Anonymous, unsecured: every service over every node of four drives, with keep low,
    two rounds: the nodes held stay within keep plus those watched, and every one is
    answered as a node that exists. Once the monitored items are gone, the nodes they
    held are dropped as other nodes are made (two looked at per node made)."""
    async with (
        opcua_gateway(_eight_drives(tmp_path)) as (_, server),
        connected(server.url) as client,
    ):
        table = _table(server)
        table.keep = 16
        ns = await client.get_namespace_index(NAMESPACE)
        ids = _drive_ids(table, ns)
        for _ in range(2):
            statuses = await _every_lookup(client, ids)
            assert "BadNodeIdUnknown" not in statuses
            _bounded(table, watched=len(ids))  # each watched by a monitored item at once
        assert table.made > len(ids)
        assert table.made - table.dropped == table.kept
        assert _untracked(table) == []
        assert _watched_nodes(table) == 0
        # No monitored item now, but the nodes they held may still be held (reading them
        # makes nothing, so nothing is looked at again): other nodes made drop them.
        others = _drive_ids(table, ns, range(5, 9))
        values = ua.ReadParameters()
        values.NodesToRead = [
            ua.ReadValueId(NodeId=n, AttributeId=ua.AttributeIds.Value) for n in others
        ]
        await client.uaclient.read(values)
        assert table.kept <= table.keep
        assert table.made - table.dropped == table.kept
        assert _untracked(table) == []


def _changed(value: ua.Variant, ns: int) -> ua.Variant:
    """A value of *value*'s type that differs from it (the same where none is at hand)."""
    kind, current = value.VariantType, value.Value
    new: object = current
    if isinstance(current, ua.LocalizedText):
        new = ua.LocalizedText("pwned")
    elif isinstance(current, ua.QualifiedName):
        new = ua.QualifiedName("pwned", ns)
    elif isinstance(current, ua.NodeId):
        new = ua.NodeId("pwned", ns)
    elif isinstance(current, bool):
        new = not current
    elif isinstance(current, int):
        new = current + 1 if current < 100 else 1
    elif isinstance(current, float):
        new = current + 1.0
    elif isinstance(current, str):
        new = "pwned"
    elif isinstance(current, list):
        new = []
    return ua.Variant(new, kind, is_array=value.is_array)


async def _read(client: Client, read: ua.ReadParameters) -> list[ua.DataValue]:
    """*read*, in requests of the server's most operations each."""
    values: list[ua.DataValue] = []
    wanted = read.NodesToRead
    for start in range(0, len(wanted), MAX_OPERATIONS):
        chunk = ua.ReadParameters()
        chunk.NodesToRead = wanted[start : start + MAX_OPERATIONS]
        values += await client.uaclient.read(chunk)
    return values


async def _snapshot(
    client: Client, ids: list[ua.NodeId]
) -> dict[tuple[str, int], tuple[object, object]]:
    """Every attribute of *ids* as a client reads it, but a variable's value (it moves)."""
    read = ua.ReadParameters()
    read.NodesToRead = [
        ua.ReadValueId(NodeId=node, AttributeId=attribute)
        for node in ids
        for attribute in _ATTRIBUTES
        if attribute != ua.AttributeIds.Value
    ]
    values = await _read(client, read)
    return {
        (str(item.NodeId.Identifier), int(item.AttributeId)): (value.StatusCode, value.Value)
        for item, value in zip(read.NodesToRead, values, strict=True)
    }


def _prototypes(table: LazyNodes) -> dict[tuple[str, str, int], object]:
    """Every prototype's attribute values (the objects shared with the drives made)."""
    out: dict[tuple[str, str, int], object] = {}
    for drive in table._drives.values():
        shape = drive.shape
        for relative, node in shape.nodes.items():
            for attribute, value in node.attributes.items():
                data = value.value
                shown = None if data is None else (id(data), data.Value, data.StatusCode)
                out[(shape.path, relative, int(attribute))] = shown
    return out


async def _attack_writes(client: Client, ids: list[ua.NodeId], ns: int) -> list[str]:
    """Write a changed value to every attribute of *ids* (as a Good and as a Bad value),
    history-update them, and add and delete nodes and references below them."""
    uaclient = client.uaclient
    read = ua.ReadParameters()
    read.NodesToRead = [
        ua.ReadValueId(NodeId=node, AttributeId=attribute)
        for node in ids
        for attribute in _ATTRIBUTES
    ]
    current = await _read(client, read)
    writes: list[ua.WriteValue] = []
    for item, value in zip(read.NodesToRead, current, strict=True):
        if not value.StatusCode.is_good() or value.Value is None:
            continue
        changed = ua.DataValue(_changed(value.Value, ns))
        bad = ua.DataValue(StatusCode=ua.StatusCode(ua.StatusCodes.BadOutOfService))
        for data in (changed, bad):
            writes.append(
                ua.WriteValue(NodeId=item.NodeId, AttributeId=item.AttributeId, Value=data)
            )
    statuses: list[str] = []

    async def answered(coroutine: Any) -> Any:
        try:
            return await coroutine
        except UaStatusCodeError as exc:
            statuses.append(ua.StatusCode(exc.code).name)
            return None

    for start in range(0, len(writes), 500):  # below the request's bound on operations
        params = ua.WriteParameters()
        params.NodesToWrite = writes[start : start + 500]
        results = await answered(uaclient.write(params))
        for write, result in zip(params.NodesToWrite, results or (), strict=False):
            # The user's write of a granted parameter's value goes to the drive (allowed).
            parameter = str(write.NodeId.Identifier).endswith("/Parameters/F002")
            if not (result.is_good() and parameter and write.AttributeId == ua.AttributeIds.Value):
                statuses.append(f"{write.NodeId.Identifier} {write.AttributeId.name} {result.name}")
    update = ua.HistoryUpdateParameters()
    update.HistoryUpdateDetails = [
        ua.UpdateDataDetails(
            NodeId=node,
            PerformInsertReplace=ua.PerformUpdateType.Replace,
            UpdateValues=[ua.DataValue(ua.Variant(1.0))],
        )
        for node in ids
    ]
    await answered(uaclient.history_update(update))
    add = ua.AddNodesItem(
        ParentNodeId=ids[0],
        ReferenceTypeId=ua.NodeId(ua.ObjectIds.HasComponent),
        RequestedNewNodeId=ua.NodeId(f"{ids[0].Identifier}/Extra", ns),
        BrowseName=ua.QualifiedName("Extra", ns),
        NodeClass=ua.NodeClass.Object,
        NodeAttributes=ua.ObjectAttributes(DisplayName=ua.LocalizedText("Extra")),
        TypeDefinition=ua.NodeId(ua.ObjectIds.BaseObjectType),
    )
    added = await answered(uaclient.add_nodes([add]))
    statuses += [r.StatusCode.name for r in added or ()]
    reference = ua.AddReferencesItem(
        SourceNodeId=ids[1],
        ReferenceTypeId=ua.NodeId(ua.ObjectIds.Organizes),
        IsForward=True,
        TargetNodeId=ua.NodeId(ua.ObjectIds.Server),
        TargetNodeClass=ua.NodeClass.Object,
    )
    references = await answered(uaclient.add_references([reference]))
    statuses += [r.name for r in references or ()]
    delete_reference = ua.DeleteReferencesItem(
        SourceNodeId=ids[0],
        ReferenceTypeId=ua.NodeId(ua.ObjectIds.HasComponent),
        IsForward=True,
        TargetNodeId=ids[1],
        DeleteBidirectional=True,
    )
    deleted_references = await answered(uaclient.delete_references([delete_reference]))
    statuses += [r.name for r in deleted_references or ()]
    deleted = await answered(
        uaclient.delete_nodes(
            ua.DeleteNodesParameters(
                NodesToDelete=[
                    ua.DeleteNodesItem(NodeId=n, DeleteTargetReferences=True) for n in ids
                ]
            )
        )
    )
    statuses += [r.name for r in (deleted[0] if deleted else ())]
    return statuses


def _drop_all(table: LazyNodes, ids: list[ua.NodeId]) -> None:
    """Drop every drive node made and unwatched, so that *ids* are made anew when read."""
    keep, table.keep = table.keep, 0
    try:
        for _ in range(len(table._kept) // 2 + 1):
            table._trim()  # what the next nodes made would do
    finally:
        table.keep = keep
    assert table.kept == 0
    assert all(node not in table._nodes for node in ids)


@pytest.mark.parametrize("who", ["anonymous", "user"])
async def test_no_write_to_a_made_node_changes_it_or_its_shape_s_other_drives(
    tmp_path: Path, client_pair: Pair, who: str
) -> None:
    """Every attribute of every node of drive 1 written, Good and Bad, history-updated, nodes
    and references added and deleted below it: anonymous on the None endpoint, and the
    user on SignAndEncrypt (who may write F002 and call methods). Nothing changes, on
    drive 1 (made, then dropped and made again), on drive 2 (the same shape: the same
    attribute value objects), on drives 3 and 4, or on the prototypes."""
    pair = client_pair if who == "user" else None
    user = USER if who == "user" else None
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (gateway, server),
        connected(server.url, pair=pair, user=user, password=PASSWORD) as client,
    ):
        await polled(gateway)
        table = _table(server)
        ns = await client.get_namespace_index(NAMESPACE)
        everything = _drive_ids(table, ns)
        target = _drive_ids(table, ns, range(1, 2))
        prototypes = _prototypes(table)
        before = await _snapshot(client, everything)
        assert before[("hall/Drive2", int(ua.AttributeIds.DisplayName))][1] == ua.Variant(
            ua.LocalizedText("Drive2")
        )
        statuses = await _attack_writes(client, target, ns)
        assert statuses
        assert not [s for s in statuses if s.endswith("Good")]
        after = await _snapshot(client, everything)
        changed = {key: (before[key], after[key]) for key in before if before[key] != after[key]}
        assert changed == {}
        _drop_all(table, everything)
        assert await _snapshot(client, everything) == before
        assert _prototypes(table) == prototypes
        assert _untracked(table) == []


async def _watch(client: Client, ids: list[ua.NodeId], attribute: ua.AttributeIds) -> Any:
    """A subscription with a monitored item on *attribute* of each of *ids*, and the values
    it is notified of."""
    seen: list[tuple[str, object]] = []

    class Handler:
        def datachange_notification(self, node: Any, value: Any, data: Any) -> None:
            seen.append((str(node.nodeid.Identifier), value))

    subscription = await client.create_subscription(50, Handler())
    handles = await subscription.subscribe_data_change(
        [client.get_node(n) for n in ids], attr=attribute
    )
    # An object has no value: its item refused; every other one made.
    refused = [h.name for h in handles if not isinstance(h, int)]
    assert set(refused) <= {"BadAttributeIdInvalid"}, refused
    return subscription, seen


def _no_watch_left(server: OpcuaServer) -> None:
    """Nothing left of a monitored item: in the table, the server's bindings, asyncua's."""
    table = _table(server)
    assert _watched_nodes(table) == 0
    assert server._watched == {}
    assert all(binding.watched == 0 for binding in server._bound.values())
    assert all(nodes.watched == 0 for nodes in server._drives.values())
    space = server.address_space
    assert space is not None
    assert space._handle_to_attribute_map == {}


async def test_nodes_pinned_by_a_session_that_vanished_are_dropped_when_it_expires(
    tmp_path: Path,
) -> None:
    """Anonymous: monitored items on every node of drive 2 (values and display names), then
    the socket closed without a word. asyncua keeps the session and its subscription
    for the session's timeout (Part 4, 6.7); when it expires, the nodes are unwatched,
    nothing of the items is left, and the next nodes made drop them."""
    async with opcua_gateway(_eight_drives(tmp_path)) as (_, server):
        table = _table(server)
        table.keep = 8
        assert server._server is not None
        server._server.iserver.min_session_timeout_ms = 500  # the test's patience
        client = Client(server.url, timeout=10)
        client.session_timeout = 1000
        await client.connect()
        ns = await client.get_namespace_index(NAMESPACE)
        ids = _drive_ids(table, ns, range(2, 3))
        await _watch(client, ids, ua.AttributeIds.Value)
        await _watch(client, ids, ua.AttributeIds.DisplayName)
        assert _watched_nodes(table) == len(ids)
        assert server._watched
        protocol = client.uaclient.protocol
        assert protocol is not None
        assert protocol.transport is not None
        protocol.transport.abort()  # no CloseSession, no DeleteSubscriptions
        with contextlib.suppress(Exception):
            await client.disconnect_socket()
        await wait_for(lambda: server.session_count == 0, "the session expired", timeout=8)
        await wait_for(lambda: _watched_nodes(table) == 0, "the items deleted", timeout=5)
        _no_watch_left(server)
        async with connected(server.url) as other:
            read = ua.ReadParameters()
            read.NodesToRead = [
                ua.ReadValueId(NodeId=n, AttributeId=ua.AttributeIds.Value)
                for n in _drive_ids(table, ns, range(5, 9))
            ]
            await other.uaclient.read(read)
        assert table.kept <= table.keep
        assert not any(node in table._nodes for node in ids[:-8])
        assert _untracked(table) == []


async def test_a_watched_display_name_is_the_drive_s_own_and_its_item_is_deleted(
    tmp_path: Path,
) -> None:
    """Anonymous: monitored items on the display and browse names of drive objects of one
    shape (made while others are dropped): each notified of its own drive's name;
    deleting them leaves nothing, and the names read the same once the nodes are
    made again."""
    async with opcua_gateway(opcua_toml(tmp_path)) as (_, server), connected(server.url) as client:
        table = _table(server)
        table.keep = 2
        ns = await client.get_namespace_index(NAMESPACE)
        objects = [ua.NodeId(f"hall/Drive{n}", ns) for n in range(1, 5)]
        shown, seen = await _watch(client, objects, ua.AttributeIds.DisplayName)
        named, names = await _watch(client, objects, ua.AttributeIds.BrowseName)
        await wait_for(lambda: len(seen) == 4 and len(names) == 4, "first notifications")
        # Churn the rest of the drives' nodes past keep while the names are watched.
        read = ua.ReadParameters()
        read.NodesToRead = [
            ua.ReadValueId(NodeId=n, AttributeId=ua.AttributeIds.DisplayName)
            for n in _drive_ids(table, ns)
        ]
        await client.uaclient.read(read)
        assert all(node in table._nodes for node in objects)
        assert sorted(seen) == [
            (f"hall/Drive{n}", ua.LocalizedText(f"Drive{n}")) for n in range(1, 5)
        ]
        assert sorted(names) == [
            (f"hall/Drive{n}", ua.QualifiedName(f"Drive{n}", ns)) for n in range(1, 5)
        ]
        await shown.delete()
        await named.delete()
        _no_watch_left(server)
        _drop_all(table, objects)
        for number, node in enumerate(objects, 1):
            name = await client.get_node(node).read_display_name()
            assert name == ua.LocalizedText(f"Drive{number}")
        assert _untracked(table) == []


async def _call(client: Client, ns: int, drive: int, method: str, *args: Any) -> str:
    """Call *method* of drive *drive*: its status's name."""
    request = ua.CallMethodRequest(
        ObjectId=ua.NodeId(f"hall/Drive{drive}", ns),
        MethodId=ua.NodeId(f"hall/Drive{drive}/{method}", ns),
        InputArguments=[ua.Variant(a) for a in args],
    )
    (result,) = await client.uaclient.call([request])
    return str(result.StatusCode.name)


async def test_a_method_dropped_and_made_again_is_still_bound(
    tmp_path: Path, client_pair: Pair
) -> None:
    """keep 2: each call's method node is dropped by the reads between calls and made
    again for the next: the user's calls still reach the drive, another drive's method
    on this object is still refused, an anonymous call still refused as such."""
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (gateway, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as client,
        connected(server.url) as anonymous,
    ):
        await polled(gateway)
        table = _table(server)
        table.keep = 2
        ns = await client.get_namespace_index(NAMESPACE)
        churn = ua.ReadParameters()
        churn.NodesToRead = [
            ua.ReadValueId(NodeId=n, AttributeId=ua.AttributeIds.BrowseName)
            for n in _drive_ids(table, ns, range(3, 5))
        ]
        calls: list[tuple[str, tuple[object, ...]]] = [
            ("TakeControl", ()),
            ("SetFrequency", (20.0,)),
            ("Run", ("forward",)),
            ("Stop", ()),
        ]
        made = 0
        for method, args in calls:
            await client.uaclient.read(churn)
            assert ua.NodeId(f"hall/Drive2/{method}", ns) not in table._nodes
            assert await _call(client, ns, 2, method, *args) == "Good", method
            assert table.made > made
            made = table.made
            assert await _call(anonymous, ns, 2, method, *args) == "BadUserAccessDenied"
        drive = gateway.drive("hall", 2)
        assert drive is not None
        await wait_for(lambda: drive.snapshot.running is False, "drive 2 stopped")
        # Drive 1's method on drive 2's object (Part 4, 5.11.2), once made, dropped, made.
        for _ in range(2):
            await client.uaclient.read(churn)
            request = ua.CallMethodRequest(
                ObjectId=ua.NodeId("hall/Drive2", ns),
                MethodId=ua.NodeId("hall/Drive1/Stop", ns),
                InputArguments=[],
            )
            (result,) = await client.uaclient.call([request])
            assert result.StatusCode.name == "BadMethodInvalid"
        assert _untracked(table) == []


def _browse_both(ids: list[ua.NodeId]) -> ua.BrowseParameters:
    """A Browse of every reference of *ids*, both ways, every field of each."""
    browse = ua.BrowseParameters()
    browse.View = ua.ViewDescription()
    browse.RequestedMaxReferencesPerNode = 0
    browse.NodesToBrowse = [
        ua.BrowseDescription(
            NodeId=node, BrowseDirection=ua.BrowseDirection.Both, IncludeSubtypes=True,
            ResultMask=63,
        )
        for node in ids
    ]  # fmt: skip
    return browse


async def _browse_all(client: Client, ids: list[ua.NodeId]) -> list[object]:
    """Every reference of *ids*, both ways, as a client sees it."""
    browse = _browse_both(ids)
    results = await client.uaclient.browse(browse)
    return [
        (
            str(node.Identifier),
            result.StatusCode.name,
            [
                (r.ReferenceTypeId, r.IsForward, r.NodeId, r.BrowseName, r.DisplayName,
                 r.NodeClass, r.TypeDefinition)
                for r in result.References
            ],
        )
        for node, result in zip(ids, results, strict=True)
    ]  # fmt: skip


_OWN = ("Node", "UnitId", "Line", "Protocol", "Online", "Monitoring/Running", "Monitoring/State")


async def _own_values(client: Client, ns: int, drives: range) -> dict[tuple[int, str], object]:
    read = ua.ReadParameters()
    read.NodesToRead = [
        ua.ReadValueId(
            NodeId=ua.NodeId(f"hall/Drive{n}/{name}", ns), AttributeId=ua.AttributeIds.Value
        )
        for n in drives
        for name in _OWN
    ]
    read.NodesToRead += [
        ua.ReadValueId(NodeId=ua.NodeId(f"hall/Drive{n}", ns), AttributeId=attribute)
        for n in drives
        for attribute in (ua.AttributeIds.DisplayName, ua.AttributeIds.Description)
    ]
    values = await client.uaclient.read(read)
    keys = [(n, name) for n in drives for name in _OWN]
    keys += [(n, name) for n in drives for name in ("DisplayName", "Description")]
    return {key: value.Value.Value for key, value in zip(keys, values, strict=True)}


async def test_values_and_browses_are_each_drive_s_own_through_churn(
    tmp_path: Path, client_pair: Pair
) -> None:
    """Drive 2 runs, the others stand: with keep 8 every read and browse drops and makes
    nodes again, and each read is still its drive's (its identity, its sample), each
    browse the same as before the churn."""
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (gateway, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as user,
        connected(server.url) as client,
    ):
        await polled(gateway)
        table = _table(server)
        ns = await client.get_namespace_index(NAMESPACE)
        ids = _drive_ids(table, ns)
        assert await _call(user, ns, 2, "TakeControl") == "Good"
        assert await _call(user, ns, 2, "SetFrequency", 30.0) == "Good"
        assert await _call(user, ns, 2, "Run", "forward") == "Good"
        drives = [gateway.drive("hall", n) for n in range(1, 5)]
        await wait_for(lambda: drives[1] is not None and drives[1].snapshot.running, "running")
        browsed = await _browse_all(client, ids)  # keep 4,096: made once
        table.keep = 8
        _drop_all(table, ids)
        dropped = table.dropped
        for _ in range(4):
            assert await _browse_all(client, ids) == browsed
            own = await _own_values(client, ns, range(1, 5))
            for number, drive in enumerate(drives, 1):
                assert drive is not None
                snapshot = drive.snapshot
                assert own[(number, "Node")] == number
                assert own[(number, "UnitId")] == snapshot.unit
                assert own[(number, "Line")] == "hall"
                assert own[(number, "Protocol")] == snapshot.protocol
                assert own[(number, "Online")] == snapshot.online
                assert own[(number, "Monitoring/Running")] == snapshot.running == (number == 2)
                assert own[(number, "Monitoring/State")] == snapshot.state
                assert own[(number, "DisplayName")] == ua.LocalizedText(f"Drive{number}")
                described = own[(number, "Description")]
                assert isinstance(described, ua.LocalizedText)
                assert f" {number} on line hall" in str(described.Text)
        assert table.dropped - dropped > 4 * (len(ids) - table.keep)
        assert table.kept <= table.keep
        assert _untracked(table) == []
        assert await _call(user, ns, 2, "Stop") == "Good"


async def test_a_browse_of_a_drive_while_its_nodes_are_dropped_is_whole(tmp_path: Path) -> None:
    """Two anonymous clients at once, keep 4: one browses drive 1 and reads its values over
    and over while the other makes drive 3 and 4's nodes, dropping drive 1's under the
    first: every browse is the one made before."""
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (_, server),
        connected(server.url) as browser,
        connected(server.url) as churner,
    ):
        table = _table(server)
        ns = await browser.get_namespace_index(NAMESPACE)
        mine = _drive_ids(table, ns, range(1, 2))
        browsed = await _browse_all(browser, mine)
        table.keep = 4
        churn = ua.ReadParameters()
        churn.NodesToRead = [
            ua.ReadValueId(NodeId=n, AttributeId=ua.AttributeIds.Value)
            for n in _drive_ids(table, ns, range(3, 5))
        ]
        done = asyncio.Event()

        async def make_others() -> int:
            rounds = 0
            while not done.is_set():
                await churner.uaclient.read(churn)
                rounds += 1
            return rounds

        others = asyncio.create_task(make_others())
        try:
            for _ in range(30):
                assert await _browse_all(browser, mine) == browsed
                for node in mine[:8]:
                    assert (await browser.get_node(node).read_browse_name()).Name
        finally:
            done.set()
            rounds = await others
        assert rounds > 1
        assert table.kept <= table.keep
        assert _untracked(table) == []


_LIMITS = {
    "read": ua.ObjectIds.Server_ServerCapabilities_OperationLimits_MaxNodesPerRead,
    "browse": ua.ObjectIds.Server_ServerCapabilities_OperationLimits_MaxNodesPerBrowse,
    "translate": (
        ua.ObjectIds.Server_ServerCapabilities_OperationLimits_MaxNodesPerTranslateBrowsePathsToNodeIds
    ),
}


async def _request(client: Client, service: str, ids: list[ua.NodeId]) -> list[str]:
    """*service* over *ids* in one request: each result's status, or the request's."""
    uaclient = client.uaclient
    try:
        if service == "read":
            read = ua.ReadParameters()
            read.NodesToRead = [
                ua.ReadValueId(NodeId=n, AttributeId=ua.AttributeIds.Value) for n in ids
            ]
            return [v.StatusCode.name for v in await uaclient.read(read)]
        if service == "browse":
            browse = ua.BrowseParameters()
            browse.View = ua.ViewDescription()
            browse.NodesToBrowse = [
                ua.BrowseDescription(NodeId=n, BrowseDirection=ua.BrowseDirection.Forward)
                for n in ids
            ]
            return [r.StatusCode.name for r in await uaclient.browse(browse)]
        paths = [
            ua.BrowsePath(
                StartingNode=n,
                RelativePath=ua.RelativePath(
                    Elements=[
                        ua.RelativePathElement(
                            ReferenceTypeId=ua.NodeId(ua.ObjectIds.HierarchicalReferences),
                            IncludeSubtypes=True,
                            TargetName=ua.QualifiedName("EngineeringUnits", n.NamespaceIndex),
                        )
                    ]
                ),
            )
            for n in ids
        ]
        translated = await uaclient.translate_browsepaths_to_nodeids(paths)
        return [r.StatusCode.name for r in translated]
    except UaStatusCodeError as exc:
        return [ua.StatusCode(exc.code).name]


@pytest.mark.parametrize("service", sorted(_LIMITS))
async def test_one_request_names_no_more_nodes_than_the_server_advertises(
    tmp_path: Path, service: str
) -> None:
    """A finding of this probe, fixed by ``_operations``: asyncua advertised 10,000 nodes
    per Read, Browse and TranslateBrowsePathsToNodeIds and served any number, each
    request in one turn of the loop, the lazy table making every node named that was not
    held. With 256 drives (none held), one anonymous request held the loop, in three runs
    each: a Read of 30,000 nodes 1.7-2.6 s lazy against 0.7-0.9 s eager; a Browse of
    5,000 0.36-0.76 s against 0.18-0.29 s; a TranslateBrowsePathsToNodeIds of 10,000
    0.78-1.14 s against 0.21-0.39 s. A request past the advertised limit is refused
    (Part 4, 7.34: BadTooManyOperations), before any node is made."""
    async with opcua_gateway(opcua_toml(tmp_path)) as (_, server), connected(server.url) as client:
        table = _table(server)
        table.keep = 8  # every lookup of the cycle below makes its node
        ns = await client.get_namespace_index(NAMESPACE)
        limit = await client.get_node(ua.NodeId(_LIMITS[service])).read_value()
        assert isinstance(limit, int)
        assert limit > 0
        ids = _drive_ids(table, ns)
        many = [ids[i % len(ids)] for i in range(limit + 1)]
        made = table.made
        statuses = await _request(client, service, many)
        assert set(statuses) == {"BadTooManyOperations"}, (len(statuses), sorted(set(statuses)))
        assert table.made == made
        assert server._defences.requests_refused["too_many_operations"] == 1


async def test_watching_the_drives_properties_leaves_nothing_once_unwatched(
    tmp_path: Path,
) -> None:
    """A finding of this probe (small), fixed: a monitored item on the value of a drive
    node no binding serves (a property: Node, UnitId, EURange, a method's arguments) is
    counted as a line counter's watcher, and ``LineCounters.watch`` kept each node's
    count, at 0 once unwatched, for good: an entry per node ever watched (some 17 a
    drive, 35,000 at 2,048 drives), though the nodes themselves are dropped."""
    async with opcua_gateway(opcua_toml(tmp_path)) as (_, server), connected(server.url) as client:
        table = _table(server)
        ns = await client.get_namespace_index(NAMESPACE)
        counters = server._counters._watched
        before = dict(counters)
        properties = [
            node
            for node in _drive_ids(table, ns)
            if node not in server._bound
            and str(node.Identifier).rpartition("/")[2]
            in {"Node", "UnitId", "Line", "Protocol", "EURange", "EngineeringUnits"}
        ]
        assert len(properties) > 20
        subscription, _ = await _watch(client, properties, ua.AttributeIds.Value)
        await subscription.delete()
        _no_watch_left(server)
        left = {node: count for node, count in counters.items() if node not in before}
        assert left == {}
