"""``sj300 gateway`` reloading its file on SIGHUP while its clients work (issue 46).

The real command in a subprocess, a real mosquitto, and clients that keep working
through every reload: a Modbus master reading every 0.2 s on one connection,
mosquitto_sub on every drive's state, an OPC UA subscription on a running drive's
frequency, and a workbench user holding that drive's control lease (its page
heartbeats). Line ``hall`` is a simulator in this process (the motor's state
is seen here); the lines added and removed are ``sim://``.

The reloads, in order: a user added; a bad file; a line added; that line changed; that
line removed with one of its drives leased and running. After each: no Modbus read
failed and its connection stayed open, the MQTT bridge did not reconnect, the lease was
kept, and one OPC UA session served throughout, the new drives in its address space.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import re
import signal
import struct
import textwrap
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import aiohttp
import pytest
from asyncua import Client, ua
from cli.clirun import TIMEOUT, closed_port, running
from mqtt_broker import running_broker
from waiting import wait_for

from sj300_async.gateway import hash_password
from sj300_async.simulator import RunState, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

from .conftest import SimLine
from .test_workbench_writes import PASSWORD_HASH, Page

NAMESPACE = "urn:sj300-async:gw1"
_PORTS = {
    "modbus": re.compile(r"modbus on 127\.0\.0\.1:(\d+)"),
    "http": re.compile(r"http on http://127\.0\.0\.1:(\d+)/"),
    "opcua": re.compile(r"opcua on (opc\.tcp://127\.0\.0\.1:\d+)"),
}
BOB_PASSWORD = "another good password"
BOB_HASH = hash_password(BOB_PASSWORD)  # once: each hash has its own salt


def _config(
    broker: int,
    hall: str,
    opcua: int,
    *,
    bob: bool = False,
    extra_lines: str = "",
    tail: str = "",
) -> str:
    """The gateway's file, OPC UA on port *opcua*."""
    bob_entry = f'[[http.users]]\nname = "bob"\npassword_hash = "{BOB_HASH}"\n' if bob else ""
    return (
        textwrap.dedent(
            f"""
            [gateway]
            id = "gw1"
            [modbus]
            listen = "127.0.0.1:0"
            [http]
            listen = "127.0.0.1:0"
            [[http.users]]
            name = "alice"
            password_hash = "{PASSWORD_HASH}"
            """
        )
        + bob_entry
        + textwrap.dedent(
            f"""
            [mqtt]
            url = "mqtt://127.0.0.1:{broker}"
            discovery = false
            [opcua]
            endpoint = "opc.tcp://127.0.0.1:{opcua}"
            security = ["None"]
            nodeset_cache = ""
            [[lines]]
            name = "hall"
            url = "{hall}"
            nodes = "1-2"
            interval_s = 0.1
            trips_interval_s = 0
            lease_s = 3
            [[lines.writes]]
            nodes = "1-2"
            control = true
            """
        )
        + extra_lines
        + tail
    )


def _line_b(nodes: str) -> str:
    return textwrap.dedent(
        f"""
        [[lines]]
        name = "b"
        url = "sim://?nodes={nodes}"
        nodes = "{nodes}"
        interval_s = 0.1
        trips_interval_s = 0
        unit_offset = 10
        lease_s = 3
        [[lines.writes]]
        nodes = "1"
        control = true
        """
    )


@dataclass
class ModbusReader:
    """Reads unit 1's first registers every 0.2 s on one connection, until stopped."""

    port: int
    reads: int = 0
    failures: list[str] = field(default_factory=list)
    closed: bool = False

    async def run(self) -> None:
        reader, writer = await asyncio.open_connection("127.0.0.1", self.port)
        tid = 0
        try:
            while True:
                tid = (tid + 1) % 65536
                writer.write(struct.pack(">HHHBBHH", tid, 0, 6, 1, 3, 0, 2))
                try:
                    async with asyncio.timeout(2.0):
                        head = await reader.readexactly(7)
                        body = await reader.readexactly(struct.unpack(">H", head[4:6])[0] - 1)
                except asyncio.IncompleteReadError:
                    self.closed = True
                    return
                except TimeoutError:
                    self.failures.append(f"read {tid} timed out")
                    continue
                if body[0] != 3:
                    self.failures.append(f"read {tid}: exception {body.hex()}")
                self.reads += 1
                await asyncio.sleep(0.2)
        finally:
            writer.close()


class Notifications:
    """An OPC UA subscription's handler: values counted, status changes kept."""

    def __init__(self) -> None:
        self.count = 0
        self.status_changes: list[object] = []

    def datachange_notification(self, node: object, value: object, data: object) -> None:
        self.count += 1

    def status_change_notification(self, status: object) -> None:
        self.status_changes.append(status)


@dataclass
class StateCounts:
    """mosquitto_sub on every drive's state topic: messages counted by ``line/node``."""

    port: int
    counts: dict[str, int] = field(default_factory=dict)

    async def run(self) -> None:
        proc = await asyncio.create_subprocess_exec(
            "mosquitto_sub", "-h", "127.0.0.1", "-p", str(self.port),
            "-t", "sj300/gw1/+/+/state", "-F", "%t",
            stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.DEVNULL,
        )  # fmt: skip
        assert proc.stdout is not None
        try:
            while line := await proc.stdout.readline():
                _, _, name, node, _ = line.decode().strip().split("/")
                key = f"{name}/{node}"
                self.counts[key] = self.counts.get(key, 0) + 1
        finally:
            proc.kill()
            await proc.wait()


@contextlib.asynccontextmanager
async def gateway_process(config: Path) -> AsyncIterator[tuple[Any, dict[str, str]]]:
    async with running("gateway", "--config", str(config)) as proc:
        assert proc.stdout is not None
        found: dict[str, str] = {}
        async with asyncio.timeout(TIMEOUT):
            while set(found) != set(_PORTS):
                line = (await proc.stdout.readline()).decode()
                assert line, "the gateway ended"
                for name, pattern in _PORTS.items():
                    if match := pattern.search(line):
                        found[name] = match[1]
        yield proc, found


async def _reloaded(proc: Any) -> str:
    """SIGHUP, then the gateway's line about it (stderr)."""
    assert proc.stderr is not None
    proc.send_signal(signal.SIGHUP)
    async with asyncio.timeout(TIMEOUT):
        while True:
            line: str = (await proc.stderr.readline()).decode().strip()
            assert line, "the gateway ended"
            if line.startswith(("reloaded ", "reload refused")):
                return line


async def _metric(session: aiohttp.ClientSession, base: str, name: str) -> float:
    async with session.get(base + "/metrics") as response:
        text = await response.text()
    match = re.search(rf"^{re.escape(name)} (\S+)$", text, re.MULTILINE)
    assert match is not None, name
    return float(match[1])


async def _keep_lease(page: Page, line: str, node: int, stop: asyncio.Event) -> list[int]:
    """The page's heartbeat, every 0.5 s (lease_s 3): the statuses it got."""
    statuses = []
    while not stop.is_set():
        status, _ = await page.post(f"/api/v1/drives/{line}/{node}/lease", {"tab": page.tab})
        statuses.append(status)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(0.5):
                await stop.wait()
    return statuses


@pytest.mark.timeout(120)
async def test_reloads_while_every_client_works(tmp_path: Path, sim_line: SimLine) -> None:
    config = tmp_path / "gateway.toml"
    (tmp_path / "broker").mkdir()
    async with running_broker(tmp_path / "broker") as broker:
        port, opcua = broker.port, closed_port()
        config.write_text(_config(port, sim_line.url, opcua))
        async with (
            gateway_process(config) as (proc, found),
            aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as session,
            aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as second,
        ):
            base = f"http://127.0.0.1:{found['http']}"
            modbus = ModbusReader(int(found["modbus"]))
            reading = asyncio.create_task(modbus.run())
            page = Page(session, base)
            assert (await page.login())[0] == 200
            stop_lease = asyncio.Event()
            leasing = asyncio.create_task(_keep_lease(page, "hall", 1, stop_lease))
            # The hall's drive 1 running, its set frequency changed after every reload.
            await _until_online(session, base, "hall", 1)
            for what, body in (
                ("lease", {}),
                ("frequency", {"hz": 10}),
                ("run", {"direction": "forward"}),
            ):
                status, answer = await page.post(
                    f"/api/v1/drives/hall/1/{what}", {"tab": page.tab, **body}
                )
                assert status == 200, answer
            client = Client(found["opcua"], timeout=10)
            await client.connect()
            ns = await client.get_namespace_index(NAMESPACE)
            online = client.get_node(ua.NodeId("hall/Drive1/Online", ns))
            notified = Notifications()
            subscription = await client.create_subscription(100, notified)
            hz = client.get_node(ua.NodeId("hall/Drive1/Monitoring/FrequencyCommandValue", ns))
            await subscription.subscribe_data_change(hz)
            states = StateCounts(port)
            subscriber = asyncio.create_task(states.run())
            await wait_for(lambda: modbus.reads >= 3, "Modbus reads", timeout=TIMEOUT)
            connects = await _metric(session, base, "sj300_mqtt_connects_total")

            setpoints = itertools.cycle((20, 30, 40))

            async def all_flowing() -> None:
                """A new set frequency for the hall's drive 1, through its lease: a new OPC
                UA value of its read-back, and a new MQTT state."""
                opc, mqtt = notified.count, states.counts.get("hall/1", 0)
                body = {"tab": page.tab, "hz": next(setpoints)}
                status, answer = await page.post("/api/v1/drives/hall/1/frequency", body)
                assert status == 200, answer
                await wait_for(lambda: notified.count > opc, "OPC UA values", timeout=TIMEOUT)
                await wait_for(
                    lambda: states.counts.get("hall/1", 0) > mqtt, "MQTT states", timeout=TIMEOUT
                )

            await all_flowing()

            # 1. A user added: bob logs in, on the running workbench.
            config.write_text(_config(port, sim_line.url, opcua, bob=True))
            said = await _reloaded(proc)
            assert said == f"reloaded {config}: [http] reconfigured"
            async with second.post(
                base + "/api/v1/login",
                json={"name": "bob", "password": BOB_PASSWORD},
                headers={"Origin": base},
            ) as response:
                assert response.status == 200
            assert await online.read_value() is True  # the same OPC UA session
            await all_flowing()

            # 2. A bad file: refused, said, counted; everything as it was.
            config.write_text(_config(port, sim_line.url, opcua, bob=True, tail="[modbuss]\n"))
            said = await _reloaded(proc)
            assert said.startswith("reload refused, still running the configuration")
            assert "modbuss: unknown key 'modbuss'" in said
            refused = 'sj300_gateway_config_reloads_total{result="refused"}'
            assert await _metric(session, base, refused) == 1
            assert await online.read_value() is True
            await all_flowing()

            # 3. A line added: polled, on every door, the doors' connections kept.
            extra = _line_b("1-2")
            config.write_text(_config(port, sim_line.url, opcua, bob=True, extra_lines=extra))
            said = await _reloaded(proc)
            assert said == f"reloaded {config}: line b added"
            reads = modbus.reads
            await wait_for(lambda: modbus.reads > reads + 2, "Modbus reads", timeout=TIMEOUT)
            reply = await _read_unit(int(found["modbus"]), 11)
            assert reply[0] == 3, reply.hex()
            async with session.get(base + "/api/v1/drives/b/2") as response:
                assert response.status == 200
            # On the OPC UA session opened before it.
            name = await client.get_node(ua.NodeId("b/Drive2/Line", ns)).read_value()
            assert name == "b"
            await wait_for(lambda: "b/2" in states.counts, "b/2's MQTT state", timeout=TIMEOUT)
            await all_flowing()

            # 4. That line changed (its nodes): replaced.
            config.write_text(
                _config(port, sim_line.url, opcua, bob=True, extra_lines=_line_b("1-3"))
            )
            said = await _reloaded(proc)
            assert said == f"reloaded {config}: line b replaced"
            await _until_online(session, base, "b", 3)
            assert await client.get_node(ua.NodeId("b/Drive3/Line", ns)).read_value() == "b"
            await all_flowing()

            # 5. A drive of that line leased and running, then the line removed: line b
            # on a simulator of this process now (its motor is seen stop).
            b_sim = SimulatedBus([1])
            b_server = await serve_tcp(b_sim)
            async with b_server:
                on_b = _line_b("1").replace(
                    '"sim://?nodes=1"', f'"tcp://127.0.0.1:{b_server.port}"'
                )
                config.write_text(_config(port, sim_line.url, opcua, bob=True, extra_lines=on_b))
                said = await _reloaded(proc)
                assert said == f"reloaded {config}: line b replaced"
                await _removed_while_running(
                    proc, config, second, base, b_sim, port, sim_line, opcua
                )
            # Through it all: no Modbus read failed, one connection, no MQTT reconnect,
            # the hall's lease kept by its heartbeats.
            stop_lease.set()
            statuses = await leasing
            assert statuses
            assert set(statuses) == {200}, statuses
            assert modbus.failures == []
            assert not modbus.closed
            assert await _metric(session, base, "sj300_mqtt_connects_total") == connects
            async with session.get(base + "/api/v1/drives/hall/1") as response:
                assert (await response.json())["control"]["holder"] is not None
            await all_flowing()
            assert await online.read_value() is True  # one OPC UA session throughout
            assert notified.status_changes == []
            await client.disconnect()
            subscriber.cancel()
            await asyncio.gather(subscriber, return_exceptions=True)
            reading.cancel()
            await asyncio.gather(reading, return_exceptions=True)
            proc.send_signal(signal.SIGTERM)
            async with asyncio.timeout(TIMEOUT):
                assert await proc.wait() == 0


async def _removed_while_running(
    proc: Any,
    config: Path,
    session: aiohttp.ClientSession,
    base: str,
    b_sim: SimulatedBus,
    port: int,
    sim_line: SimLine,
    opcua: int,
) -> None:
    other = Page(session, base)
    other.tab = "tab2"
    assert (await other.login())[0] == 200
    await _until_online(session, base, "b", 1)
    assert (await other.post("/api/v1/drives/b/1/lease", {"tab": other.tab}))[0] == 200
    status, answer = await other.post("/api/v1/drives/b/1/frequency", {"tab": other.tab, "hz": 20})
    assert status == 200, answer
    status, answer = await other.post(
        "/api/v1/drives/b/1/run", {"tab": other.tab, "direction": "forward"}
    )
    assert status == 200, answer
    loop = asyncio.get_running_loop()
    await wait_for(lambda: b_sim.drives[1].state(loop.time()).outputting, "running")
    config.write_text(_config(port, sim_line.url, opcua, bob=True))
    said = await _reloaded(proc)
    assert said == f"reloaded {config}: line b removed"
    # The reload ended once the lapse's stop was confirmed.
    state = b_sim.drives[1].state(loop.time())
    assert state in (RunState.STOPPED, RunState.DECELERATING), state


async def _until_online(session: aiohttp.ClientSession, base: str, line: str, node: int) -> None:
    """Return once the workbench's API serves *line*/*node* online."""
    async with asyncio.timeout(TIMEOUT):
        while True:
            async with session.get(f"{base}/api/v1/drives/{line}/{node}") as response:
                if response.status == 200 and (await response.json())["online"]:
                    return
            await asyncio.sleep(0.05)


async def _read_unit(port: int, unit: int) -> bytes:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(struct.pack(">HHHBBHH", 1, 0, 6, unit, 3, 0, 2))
        head = await reader.readexactly(7)
        return await reader.readexactly(struct.unpack(">H", head[4:6])[0] - 1)
    finally:
        writer.close()
