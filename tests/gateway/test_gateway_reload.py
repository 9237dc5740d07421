"""Reloading the configuration while the gateway runs: what changed changes, nothing else.

In-process gateways on simulated lines (``sim://``: the simulator is at hand, so a stop
sent on a lapse is seen on the motor). Each test writes the file, starts the gateway from
it, writes the file again and calls :meth:`Gateway.reload_file` (what SIGHUP runs).
"""

from __future__ import annotations

import asyncio
import contextlib
import textwrap
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest
from waiting import wait_for

from sj300_async.gateway import (
    Gateway,
    Heartbeat,
    Refusal,
    RunCommand,
    SetFrequency,
    load_config,
)
from sj300_async.gateway._reload import plan_reload
from sj300_async.simulator import RunState
from sj300_async.wire import Direction

from .conftest import drive_of, modbus_client, polled

SCADA = "10.0.0.5"


def _line(name: str, nodes: str = "1-2", *, control: str | None = "1-2", extra: str = "") -> str:
    grant = f'[[lines.writes]]\nnodes = "{control}"\ncontrol = true\n' if control else ""
    return (
        f'[[lines]]\nname = "{name}"\nurl = "sim://?nodes={nodes}"\nnodes = "{nodes}"\n'
        f"interval_s = 0.05\ntrips_interval_s = 0\nlease_s = 5\n{extra}\n{grant}"
    )


def _file(*lines: str, head: str = "") -> str:
    return textwrap.dedent(head) + "\n".join(lines)


@contextlib.asynccontextmanager
async def gateway_of(path: Path, text: str) -> AsyncIterator[Gateway]:
    path.write_text(text)
    async with Gateway(load_config(path)) as gateway:
        await polled(gateway)
        yield gateway


async def _running(gateway: Gateway, line: str, node: int) -> None:
    drive = drive_of(gateway, line, node)
    assert (await gateway.write(SCADA, drive, Heartbeat())).ok
    assert (await gateway.write(SCADA, drive, SetFrequency(20.0))).ok
    result = await gateway.write(SCADA, drive, RunCommand(Direction.FORWARD))
    assert result.ok, result


def _sim(gateway: Gateway, line: str) -> object:
    found = next(g for g in gateway.lines if g.config.name == line)
    assert found.bus.simulator is not None
    return found.bus.simulator


def _state(sim: object, node: int) -> RunState:
    drives = sim.drives  # type: ignore[attr-defined]
    state: RunState = drives[node].state(asyncio.get_running_loop().time())
    return state


# -- the plan ------------------------------------------------------------------------------


def test_the_plan_sorts_each_difference(tmp_path: Path) -> None:
    head = '[gateway]\nid = "gw1"\n[http]\nlisten = "127.0.0.1:0"\n'
    path = tmp_path / "gw.toml"
    path.write_text(_file(_line("a"), _line("b"), _line("c"), head=head))
    old = load_config(path)
    path.write_text(
        _file(
            _line("a", control=None),  # a grant taken away: retuned
            _line("c", "1-3", extra="unit_offset = 10"),  # other nodes: replaced
            _line("d", extra="unit_offset = 20"),  # new
            head='[gateway]\nid = "gw2"\n[http]\nlisten = "127.0.0.1:1"\n'
            '[modbus]\nlisten = "127.0.0.1:0"\n',
        )
    )
    plan = plan_reload(old, load_config(path))
    assert [c.name for c in plan.retuned] == ["a"]
    assert [c.name for c in plan.replaced] == ["c"]
    assert [c.name for c in plan.added] == ["d"]
    assert plan.removed == ("b",)
    assert plan.started == ("modbus",)
    assert plan.kept_sections == ("http",)
    assert plan.kept[0].startswith("gateway.id: 'gw1' until a restart")
    assert plan.kept[1].startswith("http: listens on listen 127.0.0.1:0 until a restart")
    same = plan_reload(old, old)
    assert same.empty
    assert same.kept == ()


# -- lines ---------------------------------------------------------------------------------


async def test_a_grant_taken_away_lapses_that_lease_and_keeps_the_others(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    async with gateway_of(path, _file(_line("a"))) as gateway:
        await _running(gateway, "a", 1)
        await _running(gateway, "a", 2)
        sim = _sim(gateway, "a")
        before = drive_of(gateway, "a", 1)
        path.write_text(_file(_line("a", control="1")))
        outcome = await gateway.reload_file(path)
        assert not outcome.refused
        assert outcome.plan is not None
        assert [c.name for c in outcome.plan.retuned] == ["a"]
        # Node 2 lost its grant: its lease lapsed, its motor stopped.
        await wait_for(lambda: _state(sim, 2) is RunState.STOPPED, "node 2 stopped", timeout=10)
        assert drive_of(gateway, "a", 2).lease.holder is None
        # Node 1 kept its grant: same drive, same lease, still running, still commandable.
        assert drive_of(gateway, "a", 1) is before
        assert before.lease.holder == SCADA
        assert _state(sim, 1).outputting
        assert (await gateway.write(SCADA, before, Heartbeat())).ok
        refused = await gateway.write(SCADA, drive_of(gateway, "a", 2), Heartbeat())
        assert refused.refusal is Refusal.NOT_ALLOWED


async def test_a_line_added_is_polled_and_served(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    head = '[modbus]\nlisten = "127.0.0.1:0"\n'
    async with (
        gateway_of(path, _file(_line("a"), head=head)) as gateway,
        modbus_client(gateway) as client,
    ):
        path.write_text(_file(_line("a"), _line("b", extra="unit_offset = 10"), head=head))
        outcome = await gateway.reload_file(path)
        assert outcome.plan is not None
        assert [c.name for c in outcome.plan.added] == ["b"]
        assert outcome.notes == ()
        await polled(gateway)
        assert [d.key for d in gateway.drives] == [("a", 1), ("a", 2), ("b", 1), ("b", 2)]
        # On the same connection: the new drive's unit answers.
        reply = await client.read_holding_registers(0, count=2, device_id=11)
        assert not reply.isError(), reply
        assert client.connected


async def test_a_line_removed_stops_its_leased_drives(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    async with gateway_of(path, _file(_line("a"), _line("b", extra="unit_offset = 10"))) as gw:
        await _running(gw, "b", 1)
        sim = _sim(gw, "b")
        removed = drive_of(gw, "b", 1)
        path.write_text(_file(_line("a")))
        outcome = await gw.reload_file(path)
        assert outcome.plan is not None
        assert outcome.plan.removed == ("b",)
        # Waited for: the reload returns once the lapse's stop is confirmed.
        assert _state(sim, 1) in (RunState.STOPPED, RunState.DECELERATING)
        assert gw.drive("b", 1) is None
        assert [line.config.name for line in gw.lines] == ["a"]
        late = await gw.write(SCADA, removed, Heartbeat())
        assert late.refusal is Refusal.UNKNOWN_TARGET


async def test_a_line_changed_otherwise_is_replaced(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    async with gateway_of(path, _file(_line("a"))) as gateway:
        old = drive_of(gateway, "a", 1)
        path.write_text(_file(_line("a", "1-3")))
        outcome = await gateway.reload_file(path)
        assert outcome.plan is not None
        assert [c.name for c in outcome.plan.replaced] == ["a"]
        await polled(gateway)
        assert [d.key for d in gateway.drives] == [("a", 1), ("a", 2), ("a", 3)]
        assert drive_of(gateway, "a", 1) is not old


async def test_a_retuned_interval_takes_at_once(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    async with gateway_of(path, _file(_line("a"))) as gateway:
        line = gateway.lines[0]
        path.write_text(_file(_line("a").replace("interval_s = 0.05", "interval_s = 0.2")))
        await gateway.reload_file(path)
        assert line.poller.interval_s == 0.2
        assert gateway.lines[0] is line


# -- the file ------------------------------------------------------------------------------


async def test_a_bad_file_changes_nothing(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    path = tmp_path / "gw.toml"
    async with gateway_of(path, _file(_line("a"))) as gateway:
        config = gateway.config
        path.write_text(_file(_line("a")) + "\n[modbuss]\n")
        outcome = await gateway.reload_file(path)
        assert outcome.refused
        assert outcome.refusal == (
            f"{path}:13: modbuss: unknown key 'modbuss' (did you mean 'modbus'?)"
        )
        assert gateway.config is config
        assert (gateway.reloads["refused"], gateway.last_reload_ok) == (1, False)
        errors = [r for r in caplog.records if r.levelname == "ERROR"]
        assert len(errors) == 1
        assert outcome.refusal in errors[0].getMessage()
        path.write_text(_file(_line("a")))
        assert not (await gateway.reload_file(path)).refused
        assert (gateway.reloads["applied"], gateway.last_reload_ok) == (1, True)


@pytest.mark.parametrize("given", ["file", "config"])
async def test_a_new_section_whose_port_is_taken_is_refused_whole(
    tmp_path: Path, given: str
) -> None:
    """Through the file (SIGHUP's path) or a configuration (``Gateway.reload``, the
    library's): the new section's port is probed first, and nothing changes."""
    path = tmp_path / "gw.toml"
    async with gateway_of(path, _file(_line("a"))) as gateway:
        with socket_listening() as port:
            head = f'[modbus]\nlisten = "127.0.0.1:{port}"\n'
            path.write_text(_file(_line("a"), _line("b", extra="unit_offset = 10"), head=head))
            if given == "file":
                outcome = await gateway.reload_file(path)
            else:
                outcome = await gateway.reload(load_config(path))
        assert outcome.refusal == (
            f"modbus: cannot listen on 127.0.0.1:{port}: Address already in use"
        )
        assert [line.config.name for line in gateway.lines] == ["a"]  # nothing changed
        assert gateway.reloads["refused"] == 1


@contextlib.contextmanager
def socket_listening() -> Iterator[int]:
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port: int = taken.getsockname()[1]
        yield port


async def test_what_needs_a_restart_is_said_and_kept(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    head = '[gateway]\nid = "gw1"\n[modbus]\nlisten = "127.0.0.1:0"\n'
    async with gateway_of(path, _file(_line("a"), head=head)) as gateway:
        server = gateway.northbounds["modbus"]
        changed = '[gateway]\nid = "gw2"\n[modbus]\nlisten = "127.0.0.2:0"\n'
        path.write_text(_file(_line("a", control=None), head=changed))
        outcome = await gateway.reload_file(path)
        assert outcome.plan is not None
        assert [c.name for c in outcome.plan.retuned] == ["a"]  # the rest was taken
        assert outcome.notes == (
            "gateway.id: 'gw1' until a restart (every topic and namespace is made of it; "
            "the file says 'gw2')",
            "modbus: listens on listen 127.0.0.1:0 until a restart (the file says listen "
            "127.0.0.2:0); the rest of [modbus] too",
        )
        assert gateway.config.gateway_id == "gw1"
        assert gateway.northbounds["modbus"] is server


async def test_sections_started_and_closed(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    async with gateway_of(path, _file(_line("a"))) as gateway:
        path.write_text(_file(_line("a"), head='[http]\nlisten = "127.0.0.1:0"\n'))
        outcome = await gateway.reload_file(path)
        assert outcome.plan is not None
        assert outcome.plan.started == ("http",)
        assert list(gateway.northbounds) == ["http"]
        path.write_text(_file(_line("a")))
        outcome = await gateway.reload_file(path)
        assert outcome.plan is not None
        assert outcome.plan.closed == ("http",)
        assert gateway.northbounds == {}


async def test_reloads_are_counted_in_the_metrics(tmp_path: Path) -> None:
    path = tmp_path / "gw.toml"
    async with gateway_of(path, _file(_line("a"))) as gateway:
        path.write_text("[[lines]")
        await gateway.reload_file(path)
        found = {
            (family.name, tuple(sample.labels.items())): sample.value
            for family in gateway.metrics()
            for sample in family.samples
            if family.name.startswith("sj300_gateway_config")
        }
        assert found == {
            ("sj300_gateway_config_reloads", (("result", "applied"),)): 0,
            ("sj300_gateway_config_reloads", (("result", "refused"),)): 1,
            ("sj300_gateway_config_last_reload_successful", ()): 0,
        }


async def test_a_workbench_user_removed_is_logged_out(tmp_path: Path) -> None:
    import aiohttp

    from .test_workbench_writes import PASSWORD, PASSWORD_HASH, Page

    path = tmp_path / "gw.toml"
    head = (
        '[http]\nlisten = "127.0.0.1:0"\n[[http.users]]\nname = "alice"\n'
        f'password_hash = "{PASSWORD_HASH}"\n'
    )
    others = '[[http.users]]\nname = "bob"\npassword_hash = "{}"\n'
    async with (
        gateway_of(path, _file(_line("a"), head=head)) as gateway,
        aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as session,
    ):
        http = gateway.northbounds["http"]
        base = f"http://127.0.0.1:{http.port}"  # type: ignore[attr-defined]
        page = Page(session, base)
        assert (await page.login())[0] == 200
        assert (await page.post("/api/v1/drives/a/1/lease", {"tab": page.tab}))[0] == 200
        without = '[http]\nlisten = "127.0.0.1:0"\n' + others.format(PASSWORD_HASH)
        path.write_text(_file(_line("a"), head=without))
        outcome = await gateway.reload_file(path)
        assert outcome.plan is not None
        assert outcome.plan.reconfigured == ("http",)
        assert gateway.northbounds["http"] is http
        status, answer = await page.post("/api/v1/drives/a/1/lease", {"tab": page.tab})
        assert status == 401, answer
        assert (await page.login(PASSWORD))[0] == 401  # alice is no one now


async def test_a_northbound_without_the_hook_is_restarted_for_changed_lines(
    tmp_path: Path,
) -> None:
    """A package's northbound written before reloads existed (the tests' JSON-lines
    writer): started again to serve the changed lines, said in the reload's notes."""
    from toynorth import JsonlNorthbound

    from sj300_async.gateway import register_northbound, unregister_northbound

    register_northbound("jsonl", "toynorth:NORTHBOUND")
    try:
        path = tmp_path / "gw.toml"
        head = '[jsonl]\npath = "states.jsonl"\n'
        async with gateway_of(path, _file(_line("a"), head=head)) as gateway:
            before = gateway.northbounds["jsonl"]
            path.write_text(_file(_line("a"), _line("b"), head=head))
            outcome = await gateway.reload_file(path)
            assert outcome.notes == (
                "[jsonl] restarted to serve the changed lines (its clients reconnect)",
            )
            after = gateway.northbounds["jsonl"]
            assert isinstance(after, JsonlNorthbound)
            assert after is not before
            await polled(gateway)
            lines = (tmp_path / "states.jsonl").read_text().splitlines()
            await wait_for(lambda: '"line": "b"' in (tmp_path / "states.jsonl").read_text(),
                           "a sample of the new line written")  # fmt: skip
            assert lines
    finally:
        unregister_northbound("jsonl")


async def test_listener_limits_change_for_the_next_connection(tmp_path: Path) -> None:
    """``[modbus]`` limits lowered by a reload: the open connection goes on, the next one
    over the new cap is closed at once; nothing restarted."""
    import struct

    path = tmp_path / "gw.toml"
    head = '[modbus]\nlisten = "127.0.0.1:0"\nmax_connections = 4\n'
    async with gateway_of(path, _file(_line("a"), head=head)) as gateway:
        server = gateway.northbounds["modbus"]
        port = server.port  # type: ignore[attr-defined]
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        request = struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, 0, 2)
        path.write_text(_file(_line("a"), head=head.replace("= 4", "= 1")))
        outcome = await gateway.reload_file(path)
        assert outcome.plan is not None
        assert outcome.plan.reconfigured == ("modbus",)
        assert outcome.notes == ()
        assert gateway.northbounds["modbus"] is server
        writer.write(request)
        assert (await reader.readexactly(9))[7] == 3  # the open one answers
        second_reader, second = await asyncio.open_connection("127.0.0.1", port)
        second.write(request)
        assert await second_reader.read() == b""  # over the new cap: closed unanswered
        second.close()
        writer.close()


async def test_the_mqtt_commands_budget_changes_on_the_same_session(tmp_path: Path) -> None:
    from cli.clirun import closed_port

    path = tmp_path / "gw.toml"
    head = f'[mqtt]\nurl = "mqtt://127.0.0.1:{closed_port()}"\ncommand_burst = 20\n'
    async with gateway_of(path, _file(_line("a"), head=head)) as gateway:
        bridge = gateway.northbounds["mqtt"]
        changed = head.replace("command_burst = 20", "command_burst = 2") + 'prefix = "other"\n'
        path.write_text(_file(_line("a"), head=changed))
        outcome = await gateway.reload_file(path)
        assert outcome.plan is not None
        assert outcome.plan.reconfigured == ("mqtt",)
        assert outcome.notes == ("[mqtt] mqtt.prefix: as it was until a restart",)
        assert gateway.northbounds["mqtt"] is bridge
        assert bridge._intake.commands.burst == 2  # type: ignore[attr-defined]
        assert bridge.config.prefix == "sj300"  # type: ignore[attr-defined]
