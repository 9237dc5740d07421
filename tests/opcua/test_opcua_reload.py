"""``[opcua]`` users changed by a reload, on the running server (issue 46).

A user added logs in at once; a user removed, or whose password changed, reads on in
the session already open, as anonymous: its next write is refused. The server, its
sessions and its subscriptions are the same throughout.
"""

from __future__ import annotations

import contextlib
from pathlib import Path

import pytest
from asyncua import ua
from asyncua.ua.uaerrors import UaStatusCodeError
from waiting import wait_for

from sj300_async.gateway import hash_password, parse_config

from .conftest import NAMESPACE, PASSWORD, USER, Pair, connected, opcua_gateway, opcua_toml, polled

NEW_PASSWORD = "a newer password"


async def _stop_status(client: object, ns: int) -> str:
    drive = client.get_node(ua.NodeId("hall/Drive1", ns))  # type: ignore[attr-defined]
    try:
        await drive.call_method(f"{ns}:Stop")
    except UaStatusCodeError as exc:
        return str(ua.StatusCode(exc.code).name)
    return "Good"


async def test_users_change_for_the_next_request(tmp_path: Path, client_pair: Pair) -> None:
    text = opcua_toml(tmp_path)
    async with opcua_gateway(text) as (gateway, server):
        await polled(gateway)
        async with connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as old:
            ns = await old.get_namespace_index(NAMESPACE)
            assert await _stop_status(old, ns) == "Good"
            # The file again, with the user's password changed and a second user.
            fresh = hash_password(NEW_PASSWORD)
            second = f'[[opcua.users]]\nname = "second"\npassword_hash = "{fresh}"\n'
            changed = (
                text.replace(
                    text[text.index("password_hash = ") :].split("\n", 1)[0],
                    f'password_hash = "{hash_password(NEW_PASSWORD)}"',
                )
                + second
            )
            outcome = await gateway.reload(parse_config(changed, "test.toml"))
            assert outcome.plan is not None
            assert outcome.plan.reconfigured == ("opcua",)
            assert outcome.notes == ()
            assert gateway.northbounds["opcua"] is server
            # The open session reads on, and may no longer write.
            online = old.get_node(ua.NodeId("hall/Drive1/Online", ns))
            assert await online.read_value() is True
            assert await _stop_status(old, ns) == "BadUserAccessDenied"
            async with connected(
                server.url, pair=client_pair, user="second", password=NEW_PASSWORD
            ) as new:
                assert await _stop_status(new, ns) == "Good"
            async with connected(
                server.url, pair=client_pair, user=USER, password=NEW_PASSWORD
            ) as again:
                assert await _stop_status(again, ns) == "Good"


def _second_line(nodes: str = "1-2") -> str:
    return (
        f'\n[[lines]]\nname = "yard"\nurl = "sim://?nodes={nodes}"\nnodes = "{nodes}"\n'
        "interval_s = 0.1\nunit_offset = 10\n"
    )


async def test_lines_added_and_removed_on_the_same_session(tmp_path: Path) -> None:
    """A line added is browsed and read on the session already open, a subscription made
    before goes on; a line removed is gone, and an item watching it is told so."""
    text = opcua_toml(tmp_path)
    async with opcua_gateway(text) as (gateway, server):
        await polled(gateway)
        async with connected(server.url) as client:
            ns = await client.get_namespace_index(NAMESPACE)
            changes: list[tuple[str, object]] = []

            class Handler:
                def datachange_notification(
                    self, node: object, value: object, data: object
                ) -> None:
                    changes.append((str(node), data.monitored_item.Value.StatusCode))  # type: ignore[attr-defined]

            subscription = await client.create_subscription(50, Handler())
            hall = client.get_node(ua.NodeId("hall/Drive1/Online", ns))
            await subscription.subscribe_data_change(hall)
            outcome = await gateway.reload(parse_config(text + _second_line(), "test.toml"))
            assert outcome.plan is not None
            assert [c.name for c in outcome.plan.added] == ["yard"]
            assert outcome.notes == ()  # nothing restarted
            assert gateway.northbounds["opcua"] is server
            await polled(gateway)
            lines = client.get_node(ua.NodeId("Lines", ns))
            names = {(await n.read_browse_name()).Name for n in await lines.get_children()}
            assert names == {"hall", "yard"}
            yard = client.get_node(ua.NodeId("yard/Drive2/Online", ns))
            assert await yard.read_value() is True
            assert await client.get_node(ua.NodeId("yard/Drive2/Line", ns)).read_value() == "yard"
            watched = await subscription.subscribe_data_change(yard)
            # The line removed: its nodes go, the item on one of them is told.
            changes.clear()
            outcome = await gateway.reload(parse_config(text, "test.toml"))
            assert outcome.plan is not None
            assert outcome.plan.removed == ("yard",)
            names = {(await n.read_browse_name()).Name for n in await lines.get_children()}
            assert names == {"hall"}
            with pytest.raises(UaStatusCodeError) as raised:
                await yard.read_value()
            assert raised.value.code == ua.StatusCodes.BadNodeIdUnknown
            await wait_for(
                lambda: any("yard/Drive2/Online" in n and not s.is_good() for n, s in changes),  # type: ignore[attr-defined]
                "the watching item told",
            )
            assert await hall.read_value() is True  # the session and the other line go on
            await subscription.unsubscribe(watched)


async def test_session_and_login_limits_change_for_the_next_session(tmp_path: Path) -> None:
    """``[opcua]`` limits lowered by a reload: the session open stays, the next one from
    the same address over the new cap is refused; nothing restarted."""
    text = opcua_toml(tmp_path, opcua_extra="max_connections_per_address = 4\n")
    async with opcua_gateway(text) as (gateway, server), connected(server.url) as first:
        ns = await first.get_namespace_index(NAMESPACE)
        async with connected(server.url):  # a second one from this address: under the cap
            pass
        lowered = text.replace("max_connections_per_address = 4", "max_connections_per_address = 1")
        changed = lowered.replace("[opcua]\n", "[opcua]\nlogin_burst = 2\n", 1)
        outcome = await gateway.reload(parse_config(changed, "test.toml"))
        assert outcome.plan is not None
        assert outcome.plan.reconfigured == ("opcua",)
        assert outcome.notes == ()
        assert gateway.northbounds["opcua"] is server
        assert await first.get_node(ua.NodeId("hall/Drive1/Online", ns)).read_value() is True
        refused = server._defences.admission.connections_refused["per_address"]
        # asyncua's client fails in a way of its own: the server's count says why.
        with contextlib.suppress(Exception):
            async with connected(server.url):
                pytest.fail("a second connection from this address, over the new cap")
        assert server._defences.admission.connections_refused["per_address"] == refused + 1
        assert server._defences.door.logins.by_address.burst == 2.0
