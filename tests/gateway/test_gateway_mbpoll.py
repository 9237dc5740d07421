"""The gateway's Modbus TCP server seen by mbpoll, a Modbus implementation that is not ours.

mbpoll (libmodbus, Debian's ``mbpoll`` package) runs as a subprocess in
one-shot mode against a gateway in the test's event loop: reads of the
identity, monitor and parameter registers with exact values, writes with
the control lease, refusals as mbpoll words them, and mbpoll processes,
pymodbus clients and the poller all on the line at once, after which the
simulator's line log shows one master and the drives hold the last values
written.

The lease is held by a client's IP address: mbpoll and pymodbus's client
both connect from 127.0.0.1, so a heartbeat by either one is the other's too.

A value the gateway serves right after its own write may come from a poll
that read the drive before the write (see the last test, which shows it):
the tests that read a written value back through the gateway first wait
for a poll of the drive that began after the write (:func:`_fresh_poll`).
"""

from __future__ import annotations

import asyncio
import logging
import re
import shutil
import time
from collections import Counter
from dataclasses import dataclass

import pytest
from pymodbus.client import AsyncModbusTcpClient
from waiting import wait_for

from sj300_async import Sample
from sj300_async import sj300 as sj3
from sj300_async.gateway import Gateway

from .conftest import (
    SimLine,
    drive_of,
    gateway_toml,
    modbus_client,
    modbus_port,
    polled,
    running_gateway,
)

WRITES = """
    [[lines.writes]]
    nodes = "1-2"
    parameters = ["A004", "F002"]
    control = true
    """
_REGISTER = re.compile(r"^\[(\d+)\]:\s+(-?\d+)$", re.MULTILINE)


def _mbpoll_path() -> str:
    path = shutil.which("mbpoll")
    if path is None:
        raise RuntimeError("mbpoll is not installed (make system-packages installs it)")
    return path


@dataclass(frozen=True)
class Mbpoll:
    """What one mbpoll run left behind."""

    args: tuple[str, ...]
    code: int
    out: str
    err: str

    @property
    def registers(self) -> dict[int, int]:
        """The values it printed, by register address (``[12008]: 600``)."""
        return {int(a): int(v) for a, v in _REGISTER.findall(self.out)}

    def values(self, first: int, count: int) -> list[int]:
        """The values of registers *first*.. *first + count - 1*, as printed."""
        assert self.code == 0, self
        got = self.registers
        return [got[a] for a in range(first, first + count)]

    def assert_written(self, count: int) -> None:
        assert self.code == 0, self
        assert f"Written {count} references." in self.out, self

    def assert_refused(self, text: str) -> None:
        """Exit status 1 and mbpoll's (libmodbus's) words for the exception on stderr."""
        assert self.code == 1, self
        assert text in self.err, self


async def mbpoll(
    port: int, unit: int, register: int, *values: int, count: int = 1, kind: str = "4"
) -> Mbpoll:
    """One mbpoll request: a read of *count* registers, or a write of *values*.

    ``-0``: PDU (0-based) addresses, as the gateway's map gives them; ``-1``:
    one request, then exit; ``-B``: 32-bit values high word first.
    """
    args = ["-m", "tcp", "-p", str(port), "-a", str(unit), "-r", str(register)]
    args += ["-t", kind, "-0", "-1", "-B", "-o", "5"]
    if not values:
        args += ["-c", str(count)]
    args += ["127.0.0.1", *map(str, values)]
    proc = await asyncio.create_subprocess_exec(
        _mbpoll_path(),
        *args,
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    try:
        out, err = await asyncio.wait_for(proc.communicate(), 15)
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    assert proc.returncode is not None
    return Mbpoll(tuple(args), proc.returncode, out.decode(), err.decode())


async def _fresh_poll(gateway: Gateway, node: int) -> None:
    """Return once *node* has been polled from start to end since now (two of its samples).

    The first sample may come from a poll that began before now; the second's began after
    the first was published.
    """
    samples: list[Sample] = []
    poller = gateway.lines[0].poller
    unsubscribe = poller.on_sample(lambda s: samples.append(s) if s.node == node else None)
    try:
        await wait_for(lambda: len(samples) >= 2, f"two samples of node {node}")
    finally:
        unsubscribe()


def _counts(value: float, per_unit: float) -> int:
    return round(value * per_unit)


async def test_mbpoll_reads_identity_monitor_and_parameters(sim_line: SimLine) -> None:
    drive = sim_line.sim.drives[3]
    drive.set_parameter("F002", 1234)  # acceleration time 12.34 s
    drive.set_parameter("A004", 555)  # maximum frequency 55.5 Hz
    async with running_gateway(gateway_toml(sim_line.url)) as gateway:
        await polled(gateway)
        port = modbus_port(gateway)
        ident, f002, f002_32, a004, monitor, status = await asyncio.gather(
            mbpoll(port, 3, 0, count=4),
            mbpoll(port, 3, 10004, count=2),
            mbpoll(port, 3, 10004, kind="4:int"),  # one 32-bit value, big-endian words
            mbpoll(port, 3, 12008, count=2),
            mbpoll(port, 3, 100, count=14),
            mbpoll(port, 3, 200, count=5, kind="3"),  # function 4 reads the same map
        )
        assert ident.values(0, 4) == [1, 0, 1, 3]  # online, fresh, SJ300, node 3
        assert f002.values(10004, 2) == [0, 1234]
        assert f002_32.values(10004, 1) == [1234]
        assert a004.values(12008, 2) == [0, 555]
        # The simulated drive's own monitor, unchanged while it stands still.
        m = drive.monitor(asyncio.get_running_loop().time())
        assert monitor.values(100, 14) == [
            _counts(m.output_frequency_hz, 100),
            _counts(m.output_current_a, 10),
            _counts(m.output_voltage_v, 10),
            0,  # stopped
            m.output_torque_percent,
            _counts(m.power_kw, 10),
            _counts(m.pid_feedback_percent, 100),
            int(m.input_terminals),
            int(m.output_terminals),
            _counts(m.frequency_conversion, 100),
            0,
            int(m.run_time_h),
            0,
            int(m.power_on_time_h),
        ]
        assert monitor.values(100, 4) == [0, 0, 0, 0]
        s = drive.status(asyncio.get_running_loop().time())
        assert status.values(200, 5) == [0, 0, int(s.a), int(s.b), int(s.c)]
        assert int(s.b) == 0  # StatusB: stopped


async def test_mbpoll_writes_with_the_lease(sim_line: SimLine) -> None:
    drive = sim_line.sim.drives[1]
    drive.set_parameter("F002", 1)  # 0.01 s: at speed on the next poll
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        await polled(gateway)
        port = modbus_port(gateway)
        state = drive_of(gateway, "hall", 1)
        (await mbpoll(port, 1, 1000, 1)).assert_written(1)  # heartbeat: the lease
        assert state.lease.holder == "127.0.0.1"
        (await mbpoll(port, 1, 1003, 2500)).assert_written(1)  # 25.00 Hz
        assert drive.parameters["F001"] == 2500
        (await mbpoll(port, 1, 1002, 1)).assert_written(1)  # run forward
        # (After a full poll: test_an_older_poll_does_not_replace_a_write_read_back.)
        await _fresh_poll(gateway, 1)
        control = (await mbpoll(port, 1, 1000, count=4)).values(1000, 4)
        assert (control[0], control[3]) == (1, 2500)  # lease held; the set frequency
        loop = asyncio.get_running_loop()
        await wait_for(lambda: abs(drive.output_hz(loop.time()) - 25) < 1e-9, "25 Hz")
        await wait_for(
            lambda: state.snapshot.output_frequency_hz == 25,
            "a poll at 25 Hz",
        )
        m = drive.monitor(loop.time())
        expected = [2500, _counts(m.output_current_a, 10), _counts(m.output_voltage_v, 10), 1]
        assert (await mbpoll(port, 1, 100, count=4)).values(100, 4) == expected
        assert min(expected) > 0  # current and voltage too
        # pymodbus's client connects from 127.0.0.1 as well: it holds mbpoll's lease.
        async with modbus_client(gateway) as client:
            assert not (await client.write_register(1003, 3000, device_id=1)).isError()
            assert drive.parameters["F001"] == 3000
        (await mbpoll(port, 1, 12008, 0, 600)).assert_written(2)  # A004 = 60.0 Hz, function 16
        assert drive.parameters["A004"] == 600
        assert (await mbpoll(port, 1, 12008, kind="4:int")).values(12008, 1) == [600]
        (await mbpoll(port, 1, 1002, 0)).assert_written(1)  # stop
        run_commands = [r.data for r in sim_line.log.requests() if r.command is sj3.Command.RUN]
        assert run_commands == [b"1", b"0"]
    assert sim_line.log.interleaved() == []


async def test_mbpoll_reports_each_refusal(sim_line: SimLine) -> None:
    text = gateway_toml(sim_line.url, line_extra=WRITES)
    async with running_gateway(text) as gateway:
        await polled(gateway)
        port = modbus_port(gateway)
        # Another address takes unit 2's lease: mbpoll (127.0.0.1) finds it busy.
        async with modbus_client(gateway, "127.0.0.2") as hmi:
            assert not (await hmi.write_register(1000, 1, device_id=2)).isError()
            results = await asyncio.gather(
                mbpoll(port, 1, 5000),
                mbpoll(port, 1, 99, count=2),
                mbpoll(port, 9, 0),
                mbpoll(port, 3, 1000, 1),  # unit 3: no grant, a read-only drive
                mbpoll(port, 1, 1002, 1),  # control without the lease
                mbpoll(port, 1, 100, 1),  # a monitor register
                mbpoll(port, 2, 1000, 1),
                mbpoll(port, 1, 1002, 7),
                mbpoll(port, 1, 12009, 600),  # half of A004
                mbpoll(port, 1, 0, kind="0"),  # coils: none
            )
    expected = [
        "Illegal data address",
        "Illegal data address",
        "Gateway path unavailable",
        "Illegal function",
        "Illegal function",
        "Illegal function",
        "Slave device or server is busy",
        "Illegal data value",
        "Illegal data value",
        "Illegal function",
    ]
    for result, text in zip(results, expected, strict=True):
        result.assert_refused(text)
    # Nothing refused reached the line: the one command is the stop of unit 2, whose
    # lease (127.0.0.2's) lapsed when the gateway stopped.
    commands = [r for r in sim_line.log.requests() if r.command in sj3.MUTATING_COMMANDS]
    assert [(r.node, r.command, r.data) for r in commands] == [(2, sj3.Command.RUN, b"0")]


async def test_mbpoll_on_a_read_only_line_is_refused(sim_line: SimLine) -> None:
    async with running_gateway(gateway_toml(sim_line.url)) as gateway:
        await polled(gateway)
        port = modbus_port(gateway)
        results = await asyncio.gather(
            mbpoll(port, 1, 1000, 1),
            mbpoll(port, 1, 1003, 2500),
            mbpoll(port, 1, 12008, 0, 600),
            mbpoll(port, 1, 5000, 1),
        )
    for result in results[:3]:
        result.assert_refused("Illegal function")
    results[3].assert_refused("Illegal data address")
    assert sim_line.sim.drives[1].parameters["A004"] == 500
    assert not any(r.command in sj3.MUTATING_COMMANDS for r in sim_line.log.requests())


async def test_mbpoll_pymodbus_and_the_poller_at_once(
    sim_line: SimLine, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="sj300_async.gateway.audit")
    sim = sim_line.sim
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        await polled(gateway)
        port = modbus_port(gateway)
        for unit in (1, 2):  # mbpoll's heartbeats: the lease of 127.0.0.1, pymodbus's too
            (await mbpoll(port, unit, 1000, 1)).assert_written(1)
        ran: Counter[str] = Counter()
        runs: list[Mbpoll] = []

        async def mb(unit: int, register: int, *values: int, count: int = 1) -> Mbpoll:
            result = await mbpoll(port, unit, register, *values, count=count)
            ran["mbpoll " + ("writes" if values else "reads")] += 1
            runs.append(result)
            return result

        async def mb_chain(unit: int, register: int, values: list[list[int]]) -> None:
            for each in values:  # one after the other: the last one is known
                (await mb(unit, register, *each)).assert_written(len(each))

        writers_done = asyncio.Event()

        async def pymodbus_reads(client: AsyncModbusTcpClient) -> None:
            i = 0
            while not writers_done.is_set() or i < 20:  # all along the writes, and then some
                unit = 1 + i % 4
                response = await client.read_holding_registers(0, count=4, device_id=unit)
                assert response.registers[0] == 1  # online (register 1: its sample's age)
                assert response.registers[2:] == [1, unit]
                parameters = await client.read_holding_registers(12008, count=2, device_id=3)
                assert parameters.registers == [0, 500]
                ran["pymodbus reads"] += 2
                i += 1

        async def pymodbus_chain(
            client: AsyncModbusTcpClient, unit: int, register: int, values: list[list[int]]
        ) -> None:
            for each in values:
                response = await client.write_registers(register, each, device_id=unit)
                assert not response.isError(), response
                ran["pymodbus writes"] += 1

        async def writers(a004: AsyncModbusTcpClient, frequency: AsyncModbusTcpClient) -> None:
            await asyncio.gather(
                # mbpoll: sequential writes (unit 1's set frequency, unit 2's F002),
                # three racing writes of unit 1's A004, and reads of every kind.
                mb_chain(1, 1003, [[1000], [2000], [3000]]),
                mb_chain(2, 10004, [[0, 100], [0, 200], [0, 300]]),
                *(mb(1, 12008, 0, value) for value in (510, 520, 530)),
                *(mb(unit, 0, count=4) for unit in (1, 2, 3, 4)),
                mb(3, 100, count=14),
                mb(4, 12008, count=2),
                # pymodbus: writes of unit 2's A004 and set frequency, a client each.
                pymodbus_chain(a004, 2, 12008, [[0, 560], [0, 580], [0, 600]]),
                pymodbus_chain(frequency, 2, 1003, [[1500], [2000], [2500]]),
            )
            writers_done.set()

        requests_before = len(sim_line.log.requests())
        cycles_before = sum(line.poller.bus_stats(line.bus).cycles for line in gateway.lines)
        started = time.perf_counter()
        async with (
            modbus_client(gateway) as reader,
            modbus_client(gateway) as a004_writer,
            modbus_client(gateway) as frequency_writer,
        ):
            await asyncio.gather(writers(a004_writer, frequency_writer), pymodbus_reads(reader))
            elapsed = time.perf_counter() - started
            await asyncio.gather(_fresh_poll(gateway, 1), _fresh_poll(gateway, 2))
            unit1 = await reader.read_holding_registers(1003, count=1, device_id=1)
            unit2 = await reader.read_holding_registers(1003, count=1, device_id=2)
            f002 = await reader.read_holding_registers(10004, count=2, device_id=2)
        line_requests = sim_line.log.requests()[requests_before:]
        cycles = sum(line.poller.bus_stats(line.bus).cycles for line in gateway.lines)
    for result in runs:
        assert result.code == 0, result
    assert sim_line.log.interleaved() == []
    # The last value each writer sent is what the drive holds, and what the gateway serves.
    drive1, drive2 = sim.drives[1].parameters, sim.drives[2].parameters
    assert (drive1["F001"], unit1.registers) == (3000, [3000])
    assert (drive2["F001"], unit2.registers) == (2500, [2500])
    assert (drive2["F002"], f002.registers) == (300, [0, 300])
    assert drive2["A004"] == 600
    # The three racing A004 writes of unit 1: the one audited last is the one the drive holds.
    audit = [r.getMessage() for r in caplog.records if r.name == "sj300_async.gateway.audit"]
    a004 = [line for line in audit if "node 1 (unit 1): parameter A004" in line]
    assert [line.rpartition(": ")[2] for line in a004] == ["ok"] * 3, a004
    last = float(a004[-1].split(" -> ")[1].split(":")[0])
    assert sim.drives[1].parameters["A004"] == round(last * 10)
    kinds = Counter(r.command.name for r in line_requests)
    print(
        f"\nat once, in {elapsed:.2f} s: "
        + ", ".join(f"{n} {what}" for what, n in sorted(ran.items()))
        + f"; the poller ran {cycles - cycles_before} cycles; the line carried "
        + ", ".join(f"{n} {name}" for name, n in kinds.most_common())
        + "; no interleaved frames"
    )


async def test_an_older_poll_does_not_replace_a_write_read_back(sim_line: SimLine) -> None:
    """A set frequency written while the poller is half-way through the drive's reads.

    The poll plan reads status, monitor, F001, A004, F002 of node 1 and publishes one sample
    at the end. The write is sent the moment the poller's F001 read goes out, so the line
    carries (arrival order) F001 read (poll), F001 write, A004 read (poll), F001 read-back
    (write), F002 read (poll): the write is confirmed (2500 read back) before the poll's
    sample, holding the F001 read before the write (0), is published. The gateway must go
    on serving the confirmed 2500 (the drive holds it), not the older poll's 0.
    """
    async with running_gateway(gateway_toml(sim_line.url, line_extra=WRITES)) as gateway:
        await polled(gateway)
        port = modbus_port(gateway)
        (await mbpoll(port, 1, 1000, 1)).assert_written(1)  # the lease of 127.0.0.1
        loop = asyncio.get_running_loop()
        parser = sj3.RequestParser()
        tap = sim_line.server.tap
        assert tap is not None
        writes: list[asyncio.Task[None]] = []
        async with modbus_client(gateway) as client:

            async def write() -> None:
                response = await client.write_register(1003, 2500, device_id=1)
                assert not response.isError(), response  # confirmed by its read-back

            def spy(direction: str, data: bytes) -> None:
                tap(direction, data)
                if direction != "rx" or writes:
                    return
                for event in parser.feed(data):
                    if (
                        isinstance(event, sj3.Request)
                        and event.node == 1
                        and event.command is sj3.Command.READ_PARAMETER
                        and event.data == b"F001"
                    ):
                        writes.append(loop.create_task(write()))

            sim_line.server.tap = spy
            await wait_for(lambda: bool(writes), "the poller's next read of node 1's F001")
            await writes[0]
            samples: list[Sample] = []
            poller = gateway.lines[0].poller
            unsubscribe = poller.on_sample(lambda s: samples.append(s) if s.node == 1 else None)
            await wait_for(lambda: bool(samples), "node 1's sample that was under way")
            unsubscribe()
        assert sim_line.sim.drives[1].parameters["F001"] == 2500
        served = (await mbpoll(port, 1, 1003)).values(1003, 1)
        assert served == [2500], (
            f"the gateway serves {served} as node 1's set frequency, confirmed 2500 by the "
            f"write's read-back: the sample of a poll that read F001 before the write "
            f"({samples[0].parameters.get('F001')} Hz) replaced it"
        )
