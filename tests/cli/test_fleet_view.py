"""``sj300 monitor --url mqtt://...``: the fleet view, against a real broker (mosquitto).

The states are published by an independent client (``mosquitto_pub``), as
a gateway's bridge would publish them, and the monitor runs as a user runs
it: a subprocess, on a pipe or a terminal. Nothing waits a fixed time for a
state: the broker is polled until it accepts connections, and a running
monitor is read line by line. ``--count 1`` shows the retained states, the
first cycle; a live state published once they are read ends it
(:func:`first_cycle`).
"""

from __future__ import annotations

import asyncio
import dataclasses
import json
import re
import sys
import time
from collections.abc import AsyncIterator, Iterable
from pathlib import Path
from typing import Any

import pytest
from mqtt_broker import Broker, running_broker

from sj300_async.cli._record import FIELDS
from sj300_async.gateway.mqtt import (
    Fleet,
    FleetUrl,
    StateMessage,
    Topics,
    follow,
    parse_fleet_url,
)
from sj300_async.wire import LocalProtocolError

from .clirun import TIMEOUT, Result, cli_env, closed_port, running, sj300, sj300_on_terminal


@pytest.fixture
async def broker(tmp_path: Path) -> AsyncIterator[Broker]:
    async with running_broker(tmp_path) as b:
        yield b


async def publish_states(
    broker: Broker, messages: Iterable[StateMessage], prefix: str = "sj300"
) -> None:
    """Every message, retained on its state topic (16 publishers at a time)."""
    room = asyncio.Semaphore(16)

    async def one(m: StateMessage) -> None:
        async with room:
            topic = Topics(m.gateway, prefix).state(m.line, m.node)
            await broker.publish(topic, m.to_json(), retain=True)

    async with asyncio.TaskGroup() as group:
        for message in messages:
            group.create_task(one(message))


def _state(gateway: str, node: int, *, line: str = "hall", **values: Any) -> StateMessage:
    """A running SJ300's state, polled a minute ago, whose values tell the drive apart."""
    fields: dict[str, Any] = {
        "output_frequency_hz": 10.0 * (ord(gateway[-1]) - ord("a") + 1) + node,
        "output_current_a": 1.5 + node,
        "output_voltage_v": 380.0 + node,
        "direction": "forward",
        "running": True,
        "tripped": False,
        "status": {"a": "RUNNING", "b": "RUNNING", "c": "CONSTANT_SPEED"},
        "parameters": {"F001": 50.0},
        "state": "running",
        **values,
    }
    return StateMessage(gateway, line, node, "sj300", time.time() - 60 + node, True, **fields)


def _fleet() -> list[StateMessage]:
    """Two gateways: gw-a 3 SJ300s (node 2 tripped), gw-b 2 SJ300s and an FR-700 on line 2."""
    tripped: dict[str, Any] = {
        "tripped": True,
        "running": False,
        "trip": "E07",
        "trip_meaning": "over-voltage",
        "direction": "stop",
        "status": {"a": "TRIP", "b": "TRIPPED", "c": "STOP"},
        "state": "tripped",
    }
    fr700 = StateMessage(
        "gw-b", "line2", 0, "fr700", time.time() - 1, True, 25.0, 2.0, 200.0, "reverse",
        True, False, status={"bits": 5}, state="running reverse",
    )  # fmt: skip
    return [
        _state("gw-a", 1),
        _state("gw-a", 2, **tripped),
        _state("gw-a", 3),
        _state("gw-b", 1),
        _state("gw-b", 4),
        fr700,
    ]


def _by_drive(result: Result) -> dict[tuple[str, str, int], dict[str, object]]:
    assert result.code == 0, result.err
    return _keyed(result.json_lines())


def _keyed(lines: list[dict[str, Any]]) -> dict[tuple[str, str, int], dict[str, object]]:
    drives = {(s["gateway"], s["line"], s["node"]): s for s in lines}
    assert len(drives) == len(lines), "a drive printed twice"
    return drives


async def first_cycle(
    broker: Broker, sent: list[StateMessage], *args: str, prefix: str = "sj300"
) -> tuple[dict[tuple[str, str, int], dict[str, object]], str]:
    """``monitor --json --count 1``: the retained states of *sent*, keyed; and stderr.

    Once it showed one per drive, a live state (the first drive's, again) ends
    the first cycle: the view stops without showing it (the next cycle's).
    """
    url = broker.url if prefix == "sj300" else f"{broker.url}/{prefix}"
    async with running("monitor", "--url", url, "--json", "--count", "1", *args) as proc:
        lines = await _lines(proc, len(sent))
        again = sent[0]
        topic = Topics(again.gateway, prefix).state(again.line, again.node)
        await broker.publish(topic, again.to_json(), retain=False)
        out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode == 0, err
    assert out == b"", "the live state, or another drive, shown"
    return _keyed(lines), err.decode()


def _assert_shown(
    drives: dict[tuple[str, str, int], dict[str, object]],
    sent: list[StateMessage],
    gone: frozenset[str] = frozenset(),
) -> None:
    """Every message of *sent* shown as itself, in the drive record's shape (what a bus
    shows too); the drives of *gone* gateways so marked."""
    assert set(drives) == {(m.gateway, m.line, m.node) for m in sent}
    for message in sent:
        shown = dict(drives[message.gateway, message.line, message.node])
        assert list(shown) == list(FIELDS)
        published = json.loads(message.to_json())
        assert set(published) <= set(FIELDS)  # each state field has its place in the record
        assert {name: shown[name] for name in published} == published
        assert shown["time"] == message.time  # the gateway's poll, a minute ago: not now
        # What only a bus knows; what only MQTT says.
        assert (shown["error"], shown["latency_s"]) == (None, None)
        assert shown["gateway_online"] is (message.gateway not in gone)


async def test_every_drive_of_both_gateways_as_json_lines(broker: Broker) -> None:
    sent = _fleet()
    await publish_states(broker, sent)
    drives, err = await first_cycle(broker, sent)
    _assert_shown(drives, sent)
    assert err == ""

    # $SJ300_URL names a broker as well; --duration ends the view (exit 0).
    result = await sj300("monitor", "--json", "--duration", "0.5", env_url=broker.url)
    _assert_shown(_by_drive(result), sent)


async def test_a_prefix_of_two_levels(broker: Broker) -> None:
    north = [_state("gw-a", 1), _state("gw-b", 2)]
    await publish_states(broker, north, prefix="plant/north")
    await publish_states(broker, [_state("gw-c", 3)])  # under sj300/: not this view's
    drives, _ = await first_cycle(broker, north, prefix="plant/north")
    _assert_shown(drives, north)
    # A trailing slash changes nothing.
    url = f"{broker.url}/plant/north/"
    result = await sj300("monitor", "--url", url, "--json", "--duration", "0.5")
    _assert_shown(_by_drive(result), north)


async def _lines(proc: asyncio.subprocess.Process, n: int) -> list[dict[str, object]]:
    assert proc.stdout is not None
    lines = []
    for _ in range(n):
        line = await asyncio.wait_for(proc.stdout.readline(), TIMEOUT)
        assert line, "the monitor ended early"
        lines.append(json.loads(line))
    return lines


async def test_malformed_messages_are_counted_and_skipped(broker: Broker) -> None:
    good = _state("gw-a", 1)
    await publish_states(broker, [good])
    topic = Topics("gw-a").state("hall", 1)
    async with running("monitor", "--url", broker.url, "--json", "--count", "2") as proc:
        assert (await _lines(proc, 1))[0]["node"] == 1  # subscribed: the retained state came
        # Live (QoS 1, one after the other): they reach the monitor in this order.
        await broker.publish(topic, "{not json", retain=False)
        wrong_type = json.loads(good.to_json()) | {"output_frequency_hz": "fast"}
        await broker.publish(topic, json.dumps(wrong_type), retain=False)
        await broker.publish(topic, _state("gw-a", 9).to_json(), retain=False)  # misrouted
        await broker.publish("sj300/gw-a/hall/x/state", good.to_json(), retain=False)
        await broker.publish("sj300/gw-a/availability", "maybe", retain=False)
        await broker.publish(topic, good.to_json(), retain=False)  # the 2nd state: the end
        out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode == 0, err
    assert [json.loads(line)["node"] for line in out.decode().splitlines()] == [1]
    assert err.decode().splitlines() == [
        "sj300 monitor: note: 5 malformed messages skipped "
        f"(first: {topic}: not JSON: Expecting property name enclosed in double quotes: "
        "line 1 column 2 (char 1))"
    ]


async def test_a_lost_broker_is_reconnected(broker: Broker) -> None:
    first = [_state("gw-a", 1), _state("gw-a", 2)]
    await publish_states(broker, first)
    # Two cycles: the retained states, then the two sent again after the reconnection.
    async with running("monitor", "--url", broker.url, "--json", "--count", "2") as proc:
        assert len(await _lines(proc, 2)) == 2
        await broker.stop()
        await broker.start()  # same port; no persistence: its retained states are gone
        again = [_state("gw-a", 1, output_frequency_hz=42.0), _state("gw-a", 2)]
        await publish_states(broker, again)
        out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode == 0, err
    lines = [json.loads(line) for line in out.decode().splitlines()]
    assert sorted(s["node"] for s in lines) == [1, 2]  # the 2 after the reconnect
    assert {s["output_frequency_hz"] for s in lines if s["node"] == 1} == {42.0}
    lost, *retries, back = err.decode().splitlines()
    assert lost.startswith(f"sj300 monitor: note: connection to {broker.url} lost (")
    assert lost.endswith("): next attempt in 0.5 s")
    # Should the broker be slow to come back: each failed attempt is a line, waits growing.
    for note, delay in zip(retries, ("1", "2", "4"), strict=False):
        assert note.startswith(f"sj300 monitor: note: cannot reconnect to {broker.url} (")
        assert note.endswith(f"): next attempt in {delay} s")
    assert back == f"sj300 monitor: note: reconnected to {broker.url}"


async def test_a_consumer_that_fails_ends_the_view_at_once(broker: Broker) -> None:
    """A reader that went away (a closed pipe) ends the subscription; it is no lost broker."""
    await publish_states(broker, [_state("gw-a", 1)])
    fleet = Fleet(parse_fleet_url(broker.url))
    links: list[str | None] = []

    def on_state(message: StateMessage) -> bool:
        raise BrokenPipeError("the reader went away")

    with pytest.raises(BrokenPipeError):
        async with asyncio.timeout(TIMEOUT):
            await follow(fleet, on_state, on_link=links.append)
    assert links == [None]  # connected once, never "lost" nor reconnected

    # The command line: a gateway goes on publishing; the view's reader takes one line.
    async def publishing() -> None:
        for hz in range(10_000):
            await publish_states(broker, [_state("gw-a", 1, output_frequency_hz=float(hz))])
            await asyncio.sleep(0.05)

    publisher = asyncio.create_task(publishing())
    try:
        piped = await asyncio.create_subprocess_shell(
            f"{sys.executable} -m sj300_async monitor --url {broker.url} --json | head -n 1",
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
            env=cli_env(),
        )
        out, err = await asyncio.wait_for(piped.communicate(), TIMEOUT)
    finally:
        publisher.cancel()
    assert json.loads(out)["node"] == 1
    assert b"Traceback" not in err, err
    assert b"unexpected error" not in err, err


async def test_on_a_terminal_a_table_of_every_drive(broker: Broker) -> None:
    sent = _fleet()
    await broker.publish("sj300/gw-a/availability", "online", retain=True)
    await broker.publish("sj300/gw-b/availability", "offline", retain=True)  # its last will: died
    await publish_states(broker, sent)
    # No gateway publishes: the first cycle (the retained states) ends --timeout after them.
    args = ("monitor", "--url", broker.url, "--count", "1", "--timeout", "2")
    result = await sj300_on_terminal(*args)
    assert result.code == 0, result.out
    screen = result.out
    assert f"sj300 monitor — fleet on {broker.url} (sj300/…)" in screen
    assert "6 drives on 2 gateways (1 offline)" in screen
    table = screen[screen.rindex("sj300 monitor — fleet") :]  # the last frame
    rows = [line.split() for line in table.splitlines()]
    header = next(row for row in rows if row[:3] == ["gateway", "line", "node"])
    assert header == [
        "gateway", "line", "node", "online", "out", "Hz", "current", "A", "voltage", "V",
        "direction", "state", "age",
    ]  # fmt: skip
    drives = [" ".join(row) for row in rows if row[:1] in (["gw-a"], ["gw-b"])]
    assert [row.split()[:4] for row in drives] == [
        ["gw-a", "hall", "01", "online"],
        ["gw-a", "hall", "02", "online"],
        ["gw-a", "hall", "03", "online"],
        ["gw-b", "hall", "01", "offline"],
        ["gw-b", "hall", "04", "offline"],
        ["gw-b", "line2", "00", "offline"],
    ]
    assert drives[0].startswith("gw-a hall 01 online 11.00 2.5 381.0 forward running ")
    assert drives[1].startswith("gw-a hall 02 online 12.00 3.5 382.0 stop tripped E07 over-volt")
    # Its gateway is gone: nobody refreshes these states.
    assert drives[3].startswith("gw-b hall 01 offline (stale) 21.00 2.5 381.0 forward running ")
    assert drives[5].startswith("gw-b line2 00 offline (stale) 25.00 2.0 200.0 reverse running rev")
    assert all(re.search(r" \d+(\.\d)? (d|h|min|s)$", row) for row in drives)  # the age

    # 80 columns: the compact layout (no direction; "stale"), the numbers whole.
    narrow = await sj300_on_terminal(*args, columns=80)
    last = narrow.out[narrow.out.rindex("sj300 monitor — fleet") :].splitlines()
    assert max(len(line.rstrip()) for line in last) <= 80
    assert any(
        line.split() == ["gateway", "line", "node", "online", "Hz", "A", "V", "state", "age"]
        for line in last
    )
    assert any(
        line.split()[:8] == ["gw-b", "hall", "01", "stale", "21.00", "2.5", "381.0", "running"]
        for line in last
    )
    assert "Traceback" not in screen


async def test_64_drives_retained_are_all_listed(broker: Broker) -> None:
    sent = [_state(gateway, node) for gateway in ("gw-a", "gw-b") for node in range(1, 33)]
    await publish_states(broker, sent)
    drives, _ = await first_cycle(broker, sent)
    _assert_shown(drives, sent)


async def test_what_a_real_gateway_publishes(broker: Broker) -> None:
    """The other side of the contract: ``sj300 gateway --mqtt`` polling simulated drives."""
    gateway = await asyncio.create_subprocess_exec(
        sys.executable, "-m", "sj300_async", "gateway", "--url", "sim://?nodes=1-3",
        "--nodes", "1-3", "--mqtt", broker.url, "--id", "gw-x",
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, env=cli_env(),
    )  # fmt: skip
    try:
        # --count 1: each drive once (the retained states; the gateway's next ends them).
        result = await sj300("monitor", "--url", broker.url, "--json", "--count", "1")
        drives = _by_drive(result)
        assert set(drives) == {("gw-x", "line1", node) for node in (1, 2, 3)}
        assert all(s["online"] is True and s["protocol"] == "sj300" for s in drives.values())
        gateway.terminate()  # a clean stop: it says offline before it goes
        await asyncio.wait_for(gateway.communicate(), TIMEOUT)
    finally:
        if gateway.returncode is None:
            gateway.kill()
            await gateway.wait()
    # Nobody publishes now: the retained states, ended --timeout after the last; no
    # drive is left to wait for (its gateway is offline), so the view ends.
    result = await sj300("monitor", "--url", broker.url, "--count", "2", "--timeout", "1")
    assert result.code == 0, result.err
    lines = result.out.splitlines()
    assert sorted(line.split()[1:4] for line in lines) == [
        [f"gw-x/line1/0{node}", "offline", "(stale)"] for node in (1, 2, 3)
    ]


async def test_an_unreachable_broker_is_one_line() -> None:
    port = closed_port()
    result = await sj300("monitor", "--url", f"mqtt://127.0.0.1:{port}", "--count", "1")
    result.assert_one_line_error(
        1, f"sj300 monitor: error: cannot connect to mqtt://127.0.0.1:{port}: "
    )


async def test_the_fleet_view_needs_no_mqtt_library() -> None:
    """The client is the gateway's own: without aiomqtt and paho it gets as far as the broker."""
    code = (
        "import sys; sys.modules['aiomqtt'] = sys.modules['paho'] = None; "
        "from sj300_async.cli import main; "
        "sys.exit(main(['monitor', '--url', 'mqtt://127.0.0.1:1']))"
    )
    proc = await asyncio.create_subprocess_exec(
        sys.executable, "-c", code, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE
    )
    out, err = await asyncio.wait_for(proc.communicate(), TIMEOUT)
    assert proc.returncode is not None
    result = Result(proc.returncode, out.decode(), err.decode())
    result.assert_one_line_error(1, "sj300 monitor: error: cannot connect to mqtt://127.0.0.1:1: ")


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (("--url", "mqtt://127.0.0.1:1", "--nodes", "1-3"), "--nodes does not apply to a broker"),
        (("--url", "mqtt://127.0.0.1:1/a/+"), "bad topic prefix 'a/+'"),
        (("--url", "mqtt://127.0.0.1:1", "--sim"), "give --url or --sim"),
    ],
)
async def test_usage_errors_are_one_line(args: tuple[str, ...], fragment: str) -> None:
    result = await sj300("monitor", *args)
    result.assert_one_line_error(2, fragment)


# --- in process: the URL and the bookkeeping ---------------------------------------------------


def test_the_url_is_taken_apart() -> None:
    assert parse_fleet_url("mqtt://broker") == FleetUrl("mqtt", "broker", 1883)
    tls = parse_fleet_url("MQTTS://me:p%40ss@[::1]/plant/north")
    assert tls == FleetUrl("mqtts", "::1", 8883, "plant/north", "me", "p@ss")
    assert tls.broker == "mqtts://[::1]:8883"  # never the password
    assert tls.state_filter == "plant/north/+/+/+/state"
    for bad in ("mqtt://:1883", "mqtt://h:99999", "mqtt://h/a//b", "mqtt://h?x=1"):
        with pytest.raises(LocalProtocolError):
            parse_fleet_url(bad)


def test_the_fleet_keeps_the_latest_state_and_clears_what_is_cleared() -> None:
    fleet = Fleet(FleetUrl("mqtt", "h", 1883))
    topic = Topics("gw-a").state("hall", 3)
    old, new = _state("gw-a", 3), _state("gw-a", 3, output_frequency_hz=1.0)
    assert fleet.receive(topic, old.to_json()) == old
    assert fleet.receive(topic, new.to_json()) == new
    assert fleet.drives == [new]
    assert fleet.gateway_online("gw-a")  # not heard yet: trusted
    assert fleet.receive("sj300/gw-a/availability", b"offline") is None
    assert not fleet.gateway_online("gw-a")
    assert fleet.receive("sj300/gw-a/availability", b"") is None  # cleared: forgotten
    assert fleet.gateway_online("gw-a")
    assert fleet.receive(topic, b"") is None  # a retained state cleared: the drive is gone
    assert fleet.drives == []
    assert fleet.malformed == 0
    assert fleet.summary() is None

    # Text reaches a terminal as it is: an escape sequence in a payload is malformed.
    hostile = dataclasses.replace(old, direction="\x1b[2Jforward")
    assert fleet.receive(topic, hostile.to_json()) is None
    assert fleet.drives == []
    assert (
        fleet.summary()
        == f"1 malformed message skipped (first: {topic}: direction is not printable text)"
    )


def test_what_stderr_shows_of_a_malformed_message_is_printable() -> None:
    fleet = Fleet(FleetUrl("mqtt", "h", 1883))
    assert fleet.receive("sj300/\x1b[2J/availability", b"maybe") is None
    assert fleet.summary() == (
        "1 malformed message skipped (first: sj300/\\x1b[2J/availability: "
        "availability is 'online' or 'offline')"
    )


async def test_json_says_when_a_gateway_is_gone(broker: Broker) -> None:
    sent = _fleet()
    await broker.publish(Topics("gw-b").availability, "offline", retain=True)  # its last will
    await publish_states(broker, sent)
    drives, _ = await first_cycle(broker, sent)
    _assert_shown(drives, sent, gone=frozenset({"gw-b"}))
