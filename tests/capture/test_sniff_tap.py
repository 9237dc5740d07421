"""The passive sniffer on a tap of the simulated line (issue 17's must-show), and ``sj300 sniff``.

A simulator is served over TCP with every byte of its line mirrored to a
tap (``serve_tcp(..., tap=)``, ``serve_tap``); :func:`sniff` listens on the
tap while a client runs a mixed workload and the test injects faults at
known points. The test's own hook on the line records which connection
each chunk came from and which way it went, so what the sniffer should
have seen is known without asking the sniffer: the frames (an independent
STX..CR split of the line, cross-checked with the simulator's counters),
what each one is, and one flag per injected fault. The sniffer must write
nothing: the tap counts what its listeners send, and the transport the
sniffer is given has its write methods replaced by spies.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import signal
import socket
import time
from collections import Counter
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from cli.clirun import TIMEOUT, closed_port, running, sj300
from waiting import wait_for

import sj300_async as sj
from sj300_async import fr700
from sj300_async import sj300 as sj3
from sj300_async.bus import _listen
from sj300_async.bus._line_connector import line_connector
from sj300_async.bus._listen import Sniffing, sniff
from sj300_async.bus._sniffer import Anomaly, SniffedFrame, Unanswered
from sj300_async.simulator import serve_tcp
from sj300_async.simulator._model import BusModel
from sj300_async.simulator._tap import TapServer, serve_tap
from sj300_async.simulator._tcp import SimulatorServer
from sj300_async.simulator.fr700 import Fr700SimulatedBus
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.sj300 import requests as rq
from sj300_async.wire._frames import FrameRole
from sj300_async.wire._pcapng import PacketDirection, read_pcapng

LINE = sj.LineSettings(19200)
#: What a TCP client's time-out allows for (open_bus's margin on a bridge; the sniffer's too).
BRIDGE_TIMING = sj.BusTiming(margin_s=0.1)

Report = SniffedFrame | Unanswered


# -- the rig -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Chunk:
    """One chunk that crossed the simulated line: whose connection, which way."""

    source: str  # "client" or "other" (the second master / another device)
    direction: str  # "rx": towards the drives, "tx": from them
    data: bytes


class WriteSpy:
    """Replaces the write methods of every transport the sniffer gets, and records calls."""

    def __init__(self) -> None:
        self.transports: list[object] = []
        self.calls: list[tuple[str, tuple[Any, ...]]] = []

    def watch(self, transport: object) -> None:
        if any(t is transport for t in self.transports):
            return
        self.transports.append(transport)
        for name in ("write", "writelines", "write_eof", "sendto"):
            if hasattr(transport, name):
                setattr(transport, name, self._recorder(name))

    def _recorder(self, name: str) -> Callable[..., None]:
        def record(*args: Any) -> None:
            self.calls.append((name, args))

        return record


@pytest.fixture
def write_spy(monkeypatch: pytest.MonkeyPatch) -> WriteSpy:
    """Every transport sniff() connects, and the one its protocol is handed, is spied on."""
    spy = WriteSpy()
    real = line_connector

    def spying(address: Any, line: sj.LineSettings) -> Any:
        connect = real(address, line)

        async def connector(factory: Any) -> Any:
            transport = await connect(factory)
            spy.watch(transport)
            return transport

        return connector

    def connection_made(self: Any, transport: Any) -> None:
        spy.watch(transport)

    monkeypatch.setattr(_listen, "line_connector", spying)
    monkeypatch.setattr(_listen._Ear, "connection_made", connection_made)
    return spy


@dataclass
class Rig:
    """A simulator on TCP with a tap, a second connection for another master, and a sniffer."""

    sim: Any
    tap: TapServer
    server: SimulatorServer
    other: SimulatorServer
    sniffing: Sniffing
    chunks: list[Chunk] = field(default_factory=list)
    reports: list[Report] = field(default_factory=list)

    @property
    def url(self) -> str:
        return f"tcp://127.0.0.1:{self.server.port}?baudrate=19200"

    @property
    def line(self) -> bytes:
        return b"".join(c.data for c in self.chunks)

    def sent(self, source: str, direction: str) -> int:
        return sum(
            len(c.data) for c in self.chunks if (c.source, c.direction) == (source, direction)
        )

    def frames(self) -> list[SniffedFrame]:
        return [r for r in self.reports if isinstance(r, SniffedFrame)]

    def unanswered(self) -> list[Unanswered]:
        return [r for r in self.reports if isinstance(r, Unanswered)]

    async def heard_everything(self) -> None:
        """Wait until the sniffer has judged every byte of the line."""
        total = len(self.line)
        await wait_for(
            lambda: sum(len(f.frame.data) for f in self.frames()) == total,
            f"the sniffer to report all {total} bytes of the line as frames",
        )

    def provenance(self) -> Iterator[tuple[SniffedFrame, Chunk]]:
        """Each frame with the chunk its first byte came in."""
        starts, at = [], 0
        for chunk in self.chunks:
            starts.append((at, chunk))
            at += len(chunk.data)
        at, i = 0, 0
        for frame in self.frames():
            while i + 1 < len(starts) and starts[i + 1][0] <= at:
                i += 1
            yield frame, starts[i][1]
            at += len(frame.frame.data)


@contextlib.asynccontextmanager
async def tapped(sim: BusModel, protocol: str = "sj300") -> AsyncIterator[Rig]:
    tap = await serve_tap("127.0.0.1", 0)
    chunks: list[Chunk] = []

    def hook(source: str) -> Callable[[str, bytes], None]:
        def mirror(direction: str, data: bytes) -> None:
            chunks.append(Chunk(source, direction, data))
            tap.mirror(direction, data)

        return mirror

    server = await serve_tcp(sim, tap=hook("client"))
    other = await serve_tcp(sim, line=server.line, tap=hook("other"))
    try:
        async with sniff(f"tcp://127.0.0.1:{tap.port}?baudrate=19200", protocol=protocol) as s:
            rig = Rig(sim, tap, server, other, s, chunks)

            async def collect() -> None:
                async for report in s.reports():
                    rig.reports.append(report)

            reader = asyncio.create_task(collect())
            await wait_for(lambda: tap.listeners == 1, "the sniffer on the tap")
            try:
                yield rig
            finally:
                reader.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await reader
    finally:
        for closing in (other, server, tap):
            closing.close()
            await closing.wait_closed()


class OtherDevice:
    """A raw connection to the same simulated line: a second master, or a device gone wrong."""

    def __init__(self, rig: Rig, writer: asyncio.StreamWriter) -> None:
        self._rig = rig
        self._writer = writer

    async def send(self, data: bytes) -> None:
        """Put *data* on the line, and wait until the line carried it."""
        before = self._rig.sent("other", "rx")
        self._writer.write(data)
        await self._writer.drain()
        await wait_for(
            lambda: self._rig.sent("other", "rx") >= before + len(data), f"{data!r} on the line"
        )


@contextlib.asynccontextmanager
async def other_device(rig: Rig) -> AsyncIterator[OtherDevice]:
    _, writer = await asyncio.open_connection("127.0.0.1", rig.other.port)
    try:
        yield OtherDevice(rig, writer)
    finally:
        writer.close()
        with contextlib.suppress(OSError):
            await writer.wait_closed()


def timeout_of(request: Any, dialect: Any = sj3.SJ300_DIALECT) -> float:
    return BRIDGE_TIMING.response_timeout(
        request, LINE, dialect.processing_s(request), dialect.reply_frame_length(request)
    )


# -- independent readings of the line -------------------------------------------------------

_SJ300_FRAME = re.compile(rb"\x02[^\x02\r]*\r")
_FR700_FRAME = re.compile(rb"[\x02\x05\x06\x15][^\x02\x05\x06\x15\r]*\r")


def split(line: bytes, frame: re.Pattern[bytes]) -> list[bytes]:
    """Frames and the runs of bytes between them, by a plain regular expression."""
    pieces, at = [], 0
    for match in frame.finditer(line):
        if match.start() > at:
            pieces.append(line[at : match.start()])
        pieces.append(match.group())
        at = match.end()
    if at < len(line):
        pieces.append(line[at:])
    return pieces


def sj300_check_ok(frame: bytes) -> bool:
    """The frame's BCC, checked by the library's bcc() on the body between STX and BCC."""
    return sj3.bcc(frame[1:-3]) == frame[-3:-1]


def fr700_check_ok(frame: bytes) -> bool:
    """An FR-700 data reply's sum, checked over station and data (STX .. ETX sum CR)."""
    etx = frame.index(b"\x03")
    return fr700.sum_check(frame[1:etx]) == frame[etx + 1 : etx + 3]


def flagged(reports: list[Report]) -> Counter[Anomaly]:
    return Counter(a for report in reports for a in report.anomalies)


# -- the must-show ------------------------------------------------------------------------


async def test_every_frame_decoded_every_injected_fault_flagged_and_nothing_written(
    write_spy: WriteSpy,
) -> None:
    sim = SimulatedBus(range(1, 4))
    injected: Counter[Anomaly] = Counter()
    async with tapped(sim) as rig, other_device(rig) as other:
        async with sj.open_bus(rig.url) as bus:
            d1, d2, d3 = bus.drive(1), bus.drive(2), bus.drive(3)
            # A clean round: status, monitor, parameters, run / stop, a broadcast, three nodes.
            await d1.read_status()
            await d2.read_monitor()
            assert await d3.read_parameter("A003") == 50.0
            await d1.write_parameter("F002", 7.5)
            await d2.set_frequency(12.5)
            await d2.run_forward()
            await bus.broadcast.stop()
            await d3.read_status()

            # A dropped reply: the request goes unanswered (the client retries and succeeds).
            sim.faults.drop_next(2)
            await d2.read_status()
            injected[Anomaly.UNANSWERED] += 1

            # A corrupted reply: a bad check code (which also answers its request).
            sim.faults.corrupt_next(1)
            await d1.read_monitor()
            injected[Anomaly.BAD_CHECK] += 1

            # A reply held past the time-out: unanswered at the time-out, then late.
            trips = rq.read_trip_history(3)
            sim.faults.delay_next(3, 1.5 * timeout_of(trips))
            await d3.read_trip_history()
            injected[Anomaly.UNANSWERED] += 1
            injected[Anomaly.LATE] += 1

            # Garbage on the line: noise (judged when the next frame starts).
            garbage = b"\x00\x7fnoise\xff"
            await other.send(garbage)
            injected[Anomaly.NOISE] += 1
            await d1.read_status()

            # Node 2's last reply again, node 2 off the line meanwhile: a duplicate, unsolicited.
            await d2.stop()
            duplicate = sj3.encode_reply(sj3.AckReply(2))
            assert rig.chunks[-1] == Chunk("client", "tx", duplicate)
            bad_frames = sim.stats.bad_frames
            sim.faults.silence(2)
            await other.send(duplicate)
            await wait_for(lambda: sim.stats.bad_frames > bad_frames, "the drives hear it")
            sim.faults.silence(2, False)
            injected[Anomaly.UNSOLICITED] += 1

            # A drive nobody asked (node 9 is not on this line): unsolicited.
            stray = sj3.encode_reply(sj3.AckReply(9))
            await other.send(stray)
            injected[Anomaly.UNSOLICITED] += 1

            # A second master asks node 3 while the client's request to node 1 waits (its
            # answer held 50 ms, within the client's time-out): two masters; the client's
            # request keeps waiting, and its answer is paired with it.
            second = rq.read_monitor(3).frame
            sim.faults.delay_next(1, 0.05)
            asked = rig.sent("client", "rx")
            call = asyncio.create_task(d1.read_monitor())
            await wait_for(lambda: rig.sent("client", "rx") > asked, "the client's request")
            await other.send(second)
            await call
            injected[Anomaly.TWO_MASTERS] += 1

            await d3.read_status()
            await d2.read_parameter("F002")
        await rig.heard_everything()

    frames = rig.frames()
    line = rig.line

    # Every byte of the line is in one reported piece, and the pieces are the frames
    # and gaps a plain STX..CR split finds.
    assert b"".join(f.frame.data for f in frames) == line
    assert [f.frame.data for f in frames] == split(line, _SJ300_FRAME)
    assert [f.number for f in frames] == list(range(1, len(frames) + 1))

    # What each piece is follows from where it came from.
    injected_frames = {garbage: FrameRole.NOISE, duplicate: FrameRole.REPLY, stray: FrameRole.REPLY}
    expected_roles = []
    for frame, chunk in rig.provenance():
        data = frame.frame.data
        if chunk.source == "other" and chunk.direction == "rx" and data != second:
            expected_roles.append(injected_frames[data])
        elif chunk.direction == "rx":
            expected_roles.append(FrameRole.REQUEST)
        else:
            expected_roles.append(FrameRole.REPLY if sj300_check_ok(data) else FrameRole.BROKEN)
    assert [f.frame.role for f in frames] == expected_roles
    # ... and every request and reply decoded, as many as the simulator counted.
    for frame in frames:
        assert frame.frame.valid == (frame.frame.message is not None), frame
    roles = Counter(f.frame.role for f in frames)
    assert roles[FrameRole.REQUEST] == sim.stats.requests
    replies_on_line = sum(1 for _, c in rig.provenance() if c.direction == "tx")
    assert replies_on_line == sim.stats.replies
    assert roles[FrameRole.REPLY] + roles[FrameRole.BROKEN] == sim.stats.replies + 2  # + injected
    assert sim.stats.requests >= 20  # the workload, the client's retries and resyncs

    # Every injected fault flagged, and nothing else.
    assert flagged(rig.reports) == injected
    assert sim.stats.dropped_replies == 1
    assert sim.stats.corrupted_replies == 1
    assert sim.stats.delayed_replies == 2
    by_number = {f.number: f for f in frames}
    [bad] = [f for f in frames if Anomaly.BAD_CHECK in f.anomalies]
    assert bad.frame.check_ok is False
    assert not sj300_check_ok(bad.frame.data)
    assert bad.frame.data[1:3] == b"01"  # node 1's (a frame that fails its check names no node)
    [noise] = [f for f in frames if Anomaly.NOISE in f.anomalies]
    assert noise.frame.data == garbage
    [two] = [f for f in frames if Anomaly.TWO_MASTERS in f.anomalies]
    assert two.frame.data == second
    unsolicited = [f for f in frames if Anomaly.UNSOLICITED in f.anomalies]
    assert [f.frame.data for f in unsolicited] == [duplicate, stray]
    [answer_to_client] = [
        f
        for f in frames
        if f.number > two.number and f.frame.message == sj3.DataReply(1, b"0" * 104)
    ]  # node 1's monitor, after the other master's request
    [client_request] = [f for f in frames if f.number == answer_to_client.answers]
    assert client_request.frame.data == rq.read_monitor(1).frame
    assert answer_to_client.anomalies == ()
    assert [u.request.frame.data for u in rig.unanswered()] == [
        rq.read_status(2).frame,
        trips.frame,
    ]
    [late] = [f for f in frames if Anomaly.LATE in f.anomalies]
    assert late.answers == rig.unanswered()[1].request.number
    assert by_number[late.answers].frame.data == trips.frame

    # Every other reply is paired with a request to its node, sooner than its time-out.
    for frame in frames:
        if frame.frame.role is FrameRole.REPLY and Anomaly.UNSOLICITED not in frame.anomalies:
            assert frame.answers is not None, frame
            request = by_number[frame.answers]
            assert request.frame.role is FrameRole.REQUEST
            assert request.frame.node == frame.frame.node
            assert frame.latency_s is not None
            assert frame.latency_s > 0
            if Anomaly.LATE not in frame.anomalies:
                assert frame.latency_s < timeout_of(request.frame.message)
    stats = rig.sniffing.stats
    assert stats.paired == roles[FrameRole.REPLY] - len(unsolicited)
    assert stats.bytes == len(line)

    # And the sniffer wrote nothing.
    assert rig.tap.bytes_from_listeners == 0
    assert rig.tap.listeners_seen == 1
    assert rig.sniffing.connections == 1
    assert write_spy.transports, "the spy saw the sniffer's transport"
    assert write_spy.calls == []


async def test_an_fr700_line_through_the_tap(write_spy: WriteSpy) -> None:
    sim = Fr700SimulatedBus((1, 2))
    async with tapped(sim, protocol="fr700") as rig:
        # ack=1: the host answers read data with ACK, which reads like a drive's ACK.
        async with sj.open_bus(rig.url + "&ack=1", protocol="fr700") as bus:
            d1, d2 = bus.drive(1), bus.drive(2)
            await d1.read_status()
            await d1.read_output_frequency()
            await d1.set_frequency(30.0)
            await d1.run_forward()
            assert await d2.read_parameter(7) == 5.0
            await d2.write_parameter(7, 6.0)
            sim.faults.drop_next(2)
            await d2.read_status()  # unanswered, then retried
            sim.faults.corrupt_next(1)
            await d1.read_output_frequency()  # bad sum check, re-output request, sent again
            await d1.stop()
        await rig.heard_everything()

    frames = rig.frames()
    assert [f.frame.data for f in frames] == split(rig.line, _FR700_FRAME)
    expected_roles = []
    for frame, chunk in rig.provenance():
        data = frame.frame.data
        if chunk.direction == "rx":
            expected_roles.append(
                FrameRole.REQUEST if data[:1] == b"\x05" else FrameRole.HOST_ANSWER
            )
        elif data[:1] == b"\x02" and not fr700_check_ok(data):
            expected_roles.append(FrameRole.BROKEN)
        else:
            expected_roles.append(FrameRole.REPLY)
    assert [f.frame.role for f in frames] == expected_roles
    roles = Counter(f.frame.role for f in frames)
    assert roles[FrameRole.REQUEST] == sim.stats.requests
    assert roles[FrameRole.REPLY] + roles[FrameRole.BROKEN] == sim.stats.replies
    assert roles[FrameRole.HOST_ANSWER] >= 5  # the host's ACKs and one re-output request
    assert flagged(rig.reports) == Counter({Anomaly.UNANSWERED: 1, Anomaly.BAD_CHECK: 1})
    [unanswered] = rig.unanswered()
    assert unanswered.request.frame.node == 2
    for frame in frames:
        if frame.frame.role is FrameRole.REPLY:
            assert frame.answers is not None, frame
    assert rig.tap.bytes_from_listeners == 0
    assert write_spy.transports
    assert write_spy.calls == []


# -- the sniffer's connection ---------------------------------------------------------------


async def test_the_sniffer_reconnects_when_the_tap_restarts() -> None:
    tap = await serve_tap("127.0.0.1", 0)
    port = tap.port
    reports: list[Report] = []
    async with sniff(f"tcp://127.0.0.1:{port}") as sniffing:

        async def collect() -> None:
            async for report in sniffing.reports():
                reports.append(report)

        reader = asyncio.create_task(collect())
        try:
            await wait_for(lambda: tap.listeners == 1, "the sniffer on the tap")
            tap.mirror("rx", rq.read_status(1).frame)
            tap.mirror("tx", b"\x020102")  # the answer's first bytes, then the tap goes
            sent = len(rq.read_status(1).frame) + 5
            await wait_for(lambda: sniffing.stats.bytes == sent, "the bytes before the restart")
            tap.close()
            await tap.wait_closed()
            # The line is gone: the frame cut short is noise (and was the request's answer).
            await wait_for(lambda: len(reports) == 2, "the cut frame reported")
            assert isinstance(reports[1], SniffedFrame)
            assert reports[1].frame.data == b"\x020102"
            assert reports[1].anomalies == (Anomaly.NOISE,)

            tap = await serve_tap("127.0.0.1", port)
            await wait_for(lambda: sniffing.connections == 2, "a reconnection", timeout=10)
            await wait_for(lambda: tap.listeners == 1, "the sniffer on the new tap")
            assert sniffing.connected.is_set()
            # Decoding goes on; a request nobody answers is reported by the timer alone.
            tap.mirror("rx", rq.read_status(2).frame)
            tap.mirror("tx", sj3.encode_reply(sj3.DataReply(2, b"02000100")))
            tap.mirror("rx", rq.read_monitor(3).frame)
            await wait_for(lambda: len(reports) == 6, "the exchange and the time-out")
            request, reply, waiting, unanswered = reports[2:]
            assert isinstance(reply, SniffedFrame)
            assert isinstance(request, SniffedFrame)
            assert (request.number, reply.answers) == (3, 3)
            assert isinstance(unanswered, Unanswered)
            assert unanswered.request == waiting
            assert tap.bytes_from_listeners == 0
        finally:
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await reader
            tap.close()
            await tap.wait_closed()


async def test_the_tap_ignores_what_a_listener_says_and_cuts_off_one_that_falls_behind() -> None:
    tap = await serve_tap("127.0.0.1", 0)
    loop = asyncio.get_running_loop()
    talker_reader, talker = await asyncio.open_connection("127.0.0.1", tap.port)
    stuck = socket.socket()  # connected, never read
    stuck.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stuck.setblocking(False)
    heard = 0

    async def listen() -> None:
        nonlocal heard
        while data := await talker_reader.read(1 << 16):
            heard += len(data)

    try:
        await loop.sock_connect(stuck, ("127.0.0.1", tap.port))
        await wait_for(lambda: tap.listeners == 2, "two listeners")
        reading = asyncio.create_task(listen())
        talker.write(b"\x02010405\r")  # a listener that tries to talk on the line
        await talker.drain()
        await wait_for(lambda: tap.bytes_from_listeners == 8, "the listener's bytes counted")
        chunk = bytes(range(256)) * 256  # 64 KiB
        for _ in range(400):  # at most 25 MiB: far more than the kernel and the backlog hold
            tap.mirror("tx", chunk)
            await wait_for(lambda: heard == tap.bytes_mirrored, "the reading listener keeps up")
            if tap.listeners_cut_off:
                break
        assert tap.listeners_cut_off == 1
        assert tap.listeners == 1  # the one that reads is still there, and got every byte
        tap.mirror("rx", b"more")
        await wait_for(lambda: heard == tap.bytes_mirrored, "more for the reading listener")
        assert tap.bytes_from_listeners == 8
        reading.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await reading
    finally:
        stuck.close()
        talker.close()
        tap.close()
        await tap.wait_closed()


async def test_sniffing_a_line_that_is_no_line_is_refused() -> None:
    for url in ("sim://?nodes=1", "replay:///tmp/none.pcapng"):
        with pytest.raises(sj.LocalProtocolError, match="no line to listen to"):
            async with sniff(url):
                pass


# -- the command line, end to end -------------------------------------------------------------


async def _read_line(stream: asyncio.StreamReader, what: str) -> str:
    line = await asyncio.wait_for(stream.readline(), TIMEOUT)
    assert line, f"{what}: end of output"
    return line.decode().rstrip("\n")


async def test_sj300_simulate_tap_and_sj300_sniff_json_end_to_end(tmp_path: Path) -> None:
    capture = tmp_path / "sniffed.pcapng"
    async with running(
        "simulate", "--listen", "tcp://127.0.0.1:0", "--tap", "tcp://127.0.0.1:0", "--nodes", "1-2"
    ) as simulate:
        assert simulate.stdout is not None
        assert simulate.stderr is not None
        tap_line = await _read_line(simulate.stdout, "simulate")
        listen_line = await _read_line(simulate.stdout, "simulate")
        tap_url = re.fullmatch(r"tap on (tcp://127\.0\.0\.1:\d+)", tap_line)
        sim_url = re.fullmatch(r"listening on (tcp://127\.0\.0\.1:\d+)", listen_line)
        assert tap_url, tap_line
        assert sim_url, listen_line
        started = time.time()
        async with running(
            "sniff", tap_url[1], "--json", "--count", "6", "--capture", str(capture)
        ) as sniffer:
            assert sniffer.stdout is not None
            assert sniffer.stderr is not None
            said = await _read_line(sniffer.stderr, "sniff")
            assert said == f"listening to {tap_url[1]}", said
            status = await sj300("--url", sim_url[1], "status", "-n", "2", "--json")
            assert status.code == 0, status.err
            out, err = await asyncio.wait_for(sniffer.communicate(), TIMEOUT)
            assert sniffer.returncode == 0, err
        finished = time.time()
        simulate.send_signal(signal.SIGTERM)
        await asyncio.wait_for(simulate.communicate(), TIMEOUT)
        assert simulate.returncode == 0

    rows = [json.loads(line) for line in out.decode().splitlines()]
    # status reads the status, the monitor and the set frequency: six frames.
    assert [r["kind"] for r in rows] == ["frame"] * 6
    assert [r["n"] for r in rows] == [1, 2, 3, 4, 5, 6]
    assert [r["role"] for r in rows] == ["request", "reply"] * 3
    assert [r["node"] for r in rows] == [2] * 6
    assert rows[0]["hex"] == rq.read_status(2).frame.hex(" ")
    assert rows[2]["hex"] == rq.read_monitor(2).frame.hex(" ")
    assert rows[4]["hex"] == rq.read_parameter(2, "F001").frame.hex(" ")
    assert [r["answers"] for r in rows] == [None, 1, None, 3, None, 5]
    assert all(r["anomalies"] == [] for r in rows)
    assert all(r["check_ok"] is True for r in rows)
    assert rows[1]["latency_ms"] > 0
    assert rows[3]["latency_ms"] > 0
    assert rows[5]["latency_ms"] > 0
    assert "read status" in rows[0]["summary"]
    # Times are Unix times, in order.
    times = [r["t"] for r in rows]
    assert times == sorted(times)
    assert started - 1 <= times[0]
    assert times[-1] <= finished + 1
    summary = err.decode().splitlines()[-1]
    assert summary.startswith("sj300 sniff: "), summary
    assert "paired 3" in summary, summary
    assert "flagged: none" in summary

    # The capture holds the same frames, with their directions.
    parsed = read_pcapng(capture.read_bytes())
    assert [i.linktype for i in parsed.interfaces] == [sj3.SJ300_DIALECT.capture_linktype]
    assert [p.data.hex(" ") for p in parsed.packets] == [r["hex"] for r in rows]
    assert [p.direction for p in parsed.packets] == [
        PacketDirection.OUTBOUND,
        PacketDirection.INBOUND,
    ] * 3
    stamps = [p.timestamp for p in parsed.packets]
    assert stamps == sorted(stamps)
    # The same instants, each side to the microsecond: within a millisecond of each other
    # (rounding both to milliseconds failed when they fell either side of a .0005).
    assert len(stamps) == len(times)
    assert all(abs(s - t) < 1e-3 for s, t in zip(stamps, times, strict=True)), (stamps, times)


async def test_sj300_sniff_refuses_a_simulator_url_in_one_line() -> None:
    result = await sj300("sniff", "sim://")
    result.assert_one_line_error(2, "sim://")


async def test_sj300_sniff_exits_with_one_line_when_nothing_listens() -> None:
    result = await sj300("sniff", f"tcp://127.0.0.1:{closed_port()}", "--json")
    assert result.code != 0, result
    assert "Traceback" not in result.err, result.err
    assert len(result.err.splitlines()) == 1, result.err
