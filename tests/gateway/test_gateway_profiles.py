"""The gateway's seams, proven from the tests alone: a third protocol and a fourth northbound.

- **A protocol is its package plus a profile.** The tests' toy protocol
  (tests/toyproto, registered here with
  :func:`~sj300_async.bus.register_protocol`) has a profile
  (tests/toyproto/_profile.py) that its dialect names: a gateway serves its
  units on ``sim://?protocol=toy`` over Modbus TCP (read here with
  pymodbus's client) and MQTT (received by a real mosquitto), with no
  library file touched. A protocol whose dialect names no profile is
  refused by the configuration, naming the file, line and key.
- **A northbound is its package plus a registry entry.** The tests' JSON-lines
  writer (tests/toynorth, registered here with
  :func:`~sj300_async.gateway.register_northbound`) brings its own
  configuration section, validated like the gateway's own, its own
  command-line flag and its own metric family, which the gateway's
  /metrics serves. It runs in the test's process through :class:`Gateway`,
  and in a ``sj300 gateway`` process whose registration happens in that
  process (a two-line wrapper around :func:`sj300_async.cli.main`).
"""

from __future__ import annotations

import asyncio
import json
import signal
import sys
import textwrap
from collections.abc import AsyncIterator, Callable, Iterator
from pathlib import Path
from typing import Any, cast

import pytest
from cli.clirun import TIMEOUT, cli_env, finished
from mqtt_broker import Broker, running_broker
from pymodbus.client import AsyncModbusTcpClient
from pymodbus.pdu import ModbusPDU
from toynorth import JsonlConfig, JsonlNorthbound
from toyproto import TOY_DIALECT, ToyDialect, ToySimulatedBus
from waiting import wait_for

from sj300_async.bus import Dialect, register_protocol, unregister_protocol
from sj300_async.gateway import (
    Gateway,
    GatewayConfigError,
    northbound_names,
    parse_config,
    register_northbound,
    unregister_northbound,
)
from sj300_async.gateway.mqtt import StateMessage, Topics

from .conftest import drive_of, metrics_port, modbus_client, polled, running_gateway
from .test_gateway_metrics import scrape
from .test_gateway_mqtt import Sub, configs, subscriber

TESTS = Path(__file__).resolve().parents[1]
#: The toy profile's unit offset (tests/toyproto/_profile.py): unit = node + 200.
TOY_UNIT = 200
#: The toy profile's RegisterLayout.protocol_id: what the identity register 2 reads.
TOY_PROTOCOL_ID = 99


@pytest.fixture
def toy_registered() -> Iterator[None]:
    register_protocol("toy", "toyproto:TOY_DIALECT")
    yield
    unregister_protocol("toy")


@pytest.fixture
def jsonl_registered() -> Iterator[None]:
    register_northbound("jsonl", "toynorth:NORTHBOUND")
    yield
    unregister_northbound("jsonl")


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with running_broker(tmp_path) as b:
        yield b


# -- a third protocol ----------------------------------------------------------------------


def toy_toml(extra: str = "") -> str:
    return textwrap.dedent(extra) + textwrap.dedent(
        """
        [[lines]]
        name = "toys"
        url = "sim://?protocol=toy&nodes=1-3"
        nodes = "1-3"
        interval_s = 0.05
        parameters = ["toy:set"]
        """
    )


def toy_simulator(gateway: Gateway) -> ToySimulatedBus:
    simulator = gateway.lines[0].bus.simulator
    assert isinstance(simulator, ToySimulatedBus)
    return simulator


def run_unit_2_at_42(gateway: Gateway) -> None:
    """Unit 2 runs at 42 (its speed and status 42, set 42); units 1 and 3 stand still."""
    toy_simulator(gateway).registers[2].update(status=42, speed=42, set=42)


async def _read(client: AsyncModbusTcpClient, unit: int, address: int, count: int = 1) -> ModbusPDU:
    return await client.read_holding_registers(address, count=count, device_id=unit)


def _code(response: ModbusPDU) -> int | None:
    return int(response.exception_code) if response.isError() else None


async def test_a_toy_line_is_served_on_modbus(toy_registered: None) -> None:
    text = toy_toml('[modbus]\nlisten = "127.0.0.1:0"\n')
    async with running_gateway(text) as gateway:
        assert [d.unit for d in gateway.drives] == [201, 202, 203]
        run_unit_2_at_42(gateway)
        await polled(gateway)
        drive = drive_of(gateway, "toys", 2)
        await wait_for(lambda: drive.snapshot.output_frequency_hz == 42.0, "a poll at 42")
        async with modbus_client(gateway) as client:
            for node in (1, 2, 3):
                ident = await _read(client, TOY_UNIT + node, 0, 4)
                assert ident.registers == [1, 0, TOY_PROTOCOL_ID, node]  # online, fresh, toy
            assert (await _read(client, 202, 100)).registers == [4200]  # 42 Hz in 0.01 Hz
            assert (await _read(client, 201, 100)).registers == [0]
            assert (await _read(client, 202, 200, 2)).registers == [1, 0]  # running, not tripped
            assert (await _read(client, 201, 200, 2)).registers == [0, 0]
            assert (await _read(client, 202, 500)).registers == [42]  # the toy's own register
            assert (await _read(client, 201, 500)).registers == [0]
            assert (await _read(client, 202, 1003)).registers == [4200]  # set: toy:set, polled
            # What a toy unit does not report is never a made-up 0: current, voltage,
            # direction are unknown (0x0B), a register of another protocol absent (0x02).
            assert _code(await _read(client, 202, 101)) == 0x0B
            assert _code(await _read(client, 202, 103)) == 0x0B
            assert _code(await _read(client, 202, 202)) == 0x02  # SJ300's status A
            assert _code(await _read(client, 202, 30014, 2)) == 0x02  # no parameter blocks
            for unit in (1, 2, 200, 204):  # not a toy unit of this gateway
                assert _code(await _read(client, unit, 0)) == 0x0A


async def test_a_toy_line_is_published_on_mqtt(toy_registered: None, broker: Broker) -> None:
    extra = f'[gateway]\nid = "gwt"\n[mqtt]\nurl = "{broker.url}"\n'
    topics = Topics("gwt")

    def states(sub: Sub, node: int) -> list[StateMessage]:
        return [StateMessage.from_json(m.payload) for m in sub.topic(topics.state("toys", node))]

    async with subscriber(broker) as sub, running_gateway(toy_toml(extra)) as gateway:
        run_unit_2_at_42(gateway)
        await wait_for(
            lambda: any(m.state == "running" for m in states(sub, 2)) and bool(states(sub, 1)),
            "unit 2's state running, unit 1's state",
        )
        await sub.barrier()
    running = next(m for m in states(sub, 2) if m.state == "running")
    assert (running.gateway, running.line, running.node) == ("gwt", "toys", 2)
    assert (running.protocol, running.online, running.running) == ("toy", True, True)
    assert (running.output_frequency_hz, running.set_frequency_hz) == (42.0, 42.0)
    assert running.status == {"raw": 42}  # the status as the toy protocol words it
    assert running.parameters == {"toy:set": 42.0}
    # Not reported by a toy unit: null, never a made-up 0.
    assert (running.output_current_a, running.output_voltage_v, running.direction) == (
        None,
        None,
        None,
    )
    assert (running.tripped, running.trip, running.trip_meaning) == (False, None, None)
    stopped = states(sub, 1)[-1]
    assert (stopped.protocol, stopped.state, stopped.running) == ("toy", "stopped", False)
    assert stopped.output_frequency_hz == 0.0
    # Home Assistant sees a toy unit as its profile names it, with the neutral sensors.
    found = {m.topic: m.json() for m in configs(sub, retained=False)}
    unit_2 = {t: b for t, b in found.items() if "/sj300_gwt_toys_2/" in t}
    assert {b["name"] for b in unit_2.values()} == {
        "Output frequency", "Output current", "Output voltage", "Status", "Events",
        "Trip records",
    }  # fmt: skip
    device = next(iter(unit_2.values()))["device"]
    assert (device["name"], device["model"], device["manufacturer"]) == (
        "gwt toys unit 2",
        "Toy unit",
        "the tests",
    )


class _Bare(ToyDialect):
    """The toy protocol under another name, its dialect naming no profile."""

    name = "bare"
    profile = None  # type: ignore[assignment]


@pytest.mark.parametrize(
    ("line", "message"),
    [
        pytest.param(
            'url = "sim://?protocol=bare"\nnodes = "1"\n',
            "gateway.toml:2: lines[0].url: protocol 'bare' has no profile (its dialect names "
            "none): the gateway and the command line cannot serve it",
            id="named-by-the-url",
        ),
        pytest.param(
            'url = "sim://"\nnodes = "1"\nprotocol = "bare"\n',
            "gateway.toml:4: lines[0].protocol: protocol 'bare' has no profile (its dialect "
            "names none): the gateway and the command line cannot serve it",
            id="named-by-the-key",
        ),
    ],
)
def test_a_protocol_without_a_profile_is_refused(line: str, message: str) -> None:
    assert TOY_DIALECT.profile is not None  # the toy protocol has one; its twin has none
    # The toy dialect is a Dialect at run time, not to mypy (tests/toyproto's own typing).
    register_protocol("bare", cast("Callable[[], Dialect[Any, Any]]", _Bare))
    try:
        with pytest.raises(GatewayConfigError) as caught:
            parse_config("[[lines]]\n" + line, "gateway.toml")
    finally:
        unregister_protocol("bare")
    assert str(caught.value) == message


# -- a fourth northbound ----------------------------------------------------------------------

JSONL_LINE = """
    [[lines]]
    name = "hall"
    url = "sim://?nodes=1-2"
    nodes = "1-2"
    interval_s = 0.05
    """


def jsonl_lines(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines()]


def jsonl_refusal(text: str) -> str:
    with pytest.raises(GatewayConfigError) as caught:
        parse_config(textwrap.dedent(text) + textwrap.dedent(JSONL_LINE), "gateway.toml")
    return str(caught.value)


def test_the_jsonl_section_is_its_northbound_s_own(jsonl_registered: None, tmp_path: Path) -> None:
    source = str(tmp_path / "gateway.toml")
    config = parse_config('[jsonl]\npath = "states.jsonl"\n' + JSONL_LINE, source)
    assert dict(config.northbounds) == {"jsonl": JsonlConfig(tmp_path / "states.jsonl")}
    assert northbound_names()[-1] == "jsonl"
    # Its errors name the file, the line and its key, as the gateway's own do.
    assert jsonl_refusal("[jsonl]\npath = 5\n") == (
        "gateway.toml:2: jsonl.path: expected a string, got integer"
    )
    assert jsonl_refusal('[jsonl]\n# where\npath = "nowhere/states.jsonl"\n') == (
        "gateway.toml:3: jsonl.path: no such directory: 'nowhere'"
    )
    assert jsonl_refusal('[jsonl]\npth = "states.jsonl"\n') == (
        "gateway.toml:2: jsonl.pth: unknown key 'pth' (did you mean 'path'?)"
    )
    assert jsonl_refusal("[jsonl]\n") == "gateway.toml:1: jsonl.path: missing required key 'path'"
    assert jsonl_refusal("x = 1\n") == (
        "gateway.toml:1: x: unknown key 'x' "
        "(use gateway, modbus, http, metrics, mqtt, sparkplug, opcua, jsonl, recorder, lines)"
    )


def test_an_unregistered_section_is_an_unknown_key() -> None:
    with pytest.raises(GatewayConfigError) as caught:
        parse_config('[jsonl]\npath = "states.jsonl"\n' + JSONL_LINE, "gateway.toml")
    assert str(caught.value) == (
        "gateway.toml:1: jsonl: unknown key 'jsonl' "
        "(use gateway, modbus, http, metrics, mqtt, sparkplug, opcua, recorder, lines)"
    )


async def test_the_jsonl_northbound_runs_in_the_gateway(
    jsonl_registered: None, tmp_path: Path
) -> None:
    path = tmp_path / "states.jsonl"
    text = '[gateway]\nid = "gwj"\n[metrics]\nlisten = "127.0.0.1:0"\n'
    text += '[jsonl]\npath = "states.jsonl"\n' + JSONL_LINE
    async with Gateway(parse_config(text, str(tmp_path / "gateway.toml"))) as gateway:
        assert list(gateway.northbounds) == ["http", "jsonl"]  # the registry's order
        jsonl = gateway.northbounds["jsonl"]
        assert isinstance(jsonl, JsonlNorthbound)
        assert jsonl.announce() == f"jsonl to {path}"
        await wait_for(lambda: len(jsonl_lines(path)) >= 6, "six snapshots written")
        before = jsonl.lines
        samples = await scrape(metrics_port(gateway))
        written = [s.value for s in samples if s.name == "toynorth_jsonl_lines_total"]
        assert len(written) == 1
        assert before <= written[0] <= jsonl.lines
    lines = jsonl_lines(path)
    assert len(lines) == jsonl.lines  # one line per snapshot, each flushed; nothing after close
    assert {(line["gateway"], line["line"], line["node"]) for line in lines} == {
        ("gwj", "hall", 1),
        ("gwj", "hall", 2),
    }
    for line in lines:
        assert (line["protocol"], line["unit"]) == ("sj300", line["node"])
    polled_ones = [line for line in lines if line["available"]]
    assert polled_ones
    assert all(
        (line["state"], line["running"], line["direction"]) == ("stopped", False, "stop")
        for line in polled_ones
    )


# -- the fourth northbound on the command line --------------------------------------------------

#: ``sj300`` with the toy northbound registered first, in its own process.
WRAPPER = textwrap.dedent(
    f"""
    import sys
    sys.path.insert(0, {str(TESTS)!r})
    from sj300_async.gateway import register_northbound
    register_northbound("jsonl", "toynorth:NORTHBOUND")
    from sj300_async.cli import main
    sys.exit(main(sys.argv[1:]))
    """
)


async def sj300_with_jsonl(*args: str) -> asyncio.subprocess.Process:
    return await asyncio.create_subprocess_exec(
        sys.executable,
        "-c",
        WRAPPER,
        *args,
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=cli_env(),
    )


async def test_the_jsonl_flag_of_sj300_gateway(tmp_path: Path) -> None:
    path = tmp_path / "states.jsonl"
    helped = await finished(await sj300_with_jsonl("gateway", "--help"))
    assert helped.code == 0, helped
    assert "--jsonl PATH" in helped.out
    bad = await finished(
        await sj300_with_jsonl(
            "gateway", "--url", "sim://", "--nodes", "1", "--jsonl", str(tmp_path / "no/x.jsonl")
        )
    )
    bad.assert_one_line_error(2)
    assert bad.err == (
        f"sj300 gateway: error: <command line>: --jsonl: no such directory: "
        f"{str(tmp_path / 'no')!r}\n"
    )
    proc = await sj300_with_jsonl(
        "gateway", "--url", "sim://?nodes=1-2", "--nodes", "1-2", "--interval", "0.05",
        "--metrics", "127.0.0.1:0", "--jsonl", str(path),
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        async with asyncio.timeout(TIMEOUT):
            metrics = (await proc.stdout.readline()).decode().strip()
            announced = (await proc.stdout.readline()).decode().strip()
        assert metrics.startswith("http on http://127.0.0.1:"), metrics
        assert announced == f"jsonl to {path}"
        port = int(metrics.rsplit(":", 1)[1].split("/")[0])
        await wait_for(lambda: len(jsonl_lines(path)) >= 4, "four snapshots written", timeout=10)
        samples = await scrape(port)
        written = [s.value for s in samples if s.name == "toynorth_jsonl_lines_total"]
        assert len(written) == 1
        assert written[0] >= 4
        proc.send_signal(signal.SIGTERM)
        result = await finished(proc)
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    assert result.code == 0, result
    assert "Traceback" not in result.err, result.err
    lines = jsonl_lines(path)
    assert len(lines) >= written[0]
    assert {(line["line"], line["node"], line["protocol"]) for line in lines} == {
        ("line1", 1, "sj300"),
        ("line1", 2, "sj300"),
    }
