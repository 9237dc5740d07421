"""``[opcua]`` users changed by a reload, on the running server (issue 46).

A user added logs in at once; a user removed, or whose password changed, reads on in
the session already open, as anonymous: its next write is refused. The server, its
sessions and its subscriptions are the same throughout.
"""

from __future__ import annotations

from pathlib import Path

from asyncua import ua
from asyncua.ua.uaerrors import UaStatusCodeError

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
