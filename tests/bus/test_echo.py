"""Local echo: only a whole, exact copy of a written frame is stripped; ``auto`` finds out.

An RS-485 adapter without echo suppression hands the host its own bytes back
before the drive answers. :class:`EchoingAdapter` is such an adapter in front
of the scripted peer (SJ300) or the simulator (FR-700), on the real loopback
transport, whose LineFaults split what reaches the host into fragments.
"""

from __future__ import annotations

import asyncio
import contextlib
import random
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any

import pytest

import sj300_async as sj
from sj300_async import bus as sjbus
from sj300_async import fr700 as fr
from sj300_async import sj300 as sj3
from sj300_async.bus._bus import Bus
from sj300_async.fr700 import requests as frq
from sj300_async.simulator import SimulatorEndpoint
from sj300_async.simulator.fr700 import Fr700SimulatedBus
from sj300_async.sj300 import requests as rq
from sj300_async.transports import LineFaults, loopback_connector
from sj300_async.transports._loopback import Peer
from sj300_async.wire import BadFrame, BadFrameReason, Discarded
from sj300_async.wire._line import INSTANT_LINE

from .scripted import Frames, Responder, ScriptedPeer, ack, answer_all, status

ROUNDS = 5  # four transactions each: 20


def unchanged(data: bytes) -> bytes:
    return data


@dataclass
class EchoingAdapter:
    """An adapter that hands every written byte back first, then passes it to the line.

    The echo goes back as the host wrote it (one chunk per write; LineFaults
    towards the host may split it), before the device behind can answer.
    """

    inner: Peer
    send: Callable[[bytes], object]
    echoing: bool = True
    #: Latency of a device server: the echo, and the request to the device, come this late.
    delay_s: float = 0.0
    #: What the echo becomes on the way back (noise on the adapter's receiver).
    damage: Callable[[bytes], bytes] = unchanged

    def data_received(self, data: bytes) -> None:
        if self.delay_s:
            asyncio.get_running_loop().call_later(self.delay_s, self._pass, data)
        else:
            self._pass(data)

    def _pass(self, data: bytes) -> None:
        if self.echoing:
            self.send(self.damage(data))
        self.inner.data_received(data)

    def close(self) -> None:
        self.inner.close()


@dataclass
class EchoRig:
    bus: Bus[Any, Any]
    adapters: list[EchoingAdapter] = field(default_factory=list)
    trace: list[sjbus.TraceRecord] = field(default_factory=list)

    @property
    def stats(self) -> sjbus.BusStats:
        return self.bus.stats

    def written(self) -> list[bytes]:
        return [r.data for r in self.trace if r.direction == "tx"]

    def parsed(self) -> list[object]:
        """Every event the parser produced from the chunks received, in order."""
        return [e for r in self.trace if r.direction == "rx" for e in r.events]


def bytewise() -> LineFaults:
    return LineFaults(rng=random.Random(1), fragment_max=1)


def small_pieces() -> LineFaults:
    return LineFaults(rng=random.Random(7), fragment_max=3)


#: How the bytes reach the host: as sent, one byte per chunk, in pieces of 1..3.
CHUNKING: dict[str, Callable[[], LineFaults | None]] = {
    "whole": lambda: None,
    "bytewise": bytewise,
    "pieces": small_pieces,
}


@contextlib.asynccontextmanager
async def sj300_line(
    respond: Responder = answer_all,
    *,
    strip_echo: bool | None,
    echoing: bool = True,
    to_host: LineFaults | None = None,
    delay_s: float = 0.0,
    damage: Callable[[bytes], bytes] = unchanged,
    **bus_kwargs: Any,
) -> AsyncIterator[EchoRig]:
    """An SJ300 bus to the scripted peer behind an (optionally) echoing adapter."""
    rig = EchoRig(bus=None)  # type: ignore[arg-type]  # set below

    def factory(send: Callable[[bytes], None]) -> EchoingAdapter:
        adapter = EchoingAdapter(ScriptedPeer(respond, send), send, echoing, delay_s, damage)
        rig.adapters.append(adapter)
        return adapter

    bus_kwargs.setdefault("timing", sj.BusTiming(margin_s=0.05))
    rig.bus = Bus(
        loopback_connector(factory, to_host=to_host),
        description="echo test",
        line=INSTANT_LINE,
        trace=rig.trace.append,
        strip_echo=strip_echo,
        **bus_kwargs,
    )
    async with rig.bus:
        yield rig


def close_shave(request: sj3.Request) -> Frames:
    """A drive whose answers start like the requests, node 1's status in all but its last byte."""
    if request.command is sj3.Command.READ_STATUS and request.node == 1:
        return [(0.0, status(1, a=4, b=5, c=3))]
    return answer_all(request)


CLOSE_SHAVE_STATUS = sj.InverterStatus(sj.StatusA(4), sj.StatusB(5), sj.StatusC(3))


def test_the_close_shave_reply_starts_as_its_request() -> None:
    request = rq.read_status(1).frame
    reply = status(1, a=4, b=5, c=3)
    assert len(request) == 8
    assert reply[:7] == request[:7]  # STX, node, "04", and the BCC "05" too
    assert reply[7] != request[7]
    assert ack(1)[:3] == rq.set_frequency(1, 12.5).frame[:3]  # STX + node


async def twenty_sj300_transactions(rig: EchoRig, *, broadcast: bool = False) -> None:
    """Four transactions a round, each answer sharing its request's first bytes."""
    d1, d2 = rig.bus.drive(1), rig.bus.drive(2)
    for n in range(ROUNDS):
        assert await d1.read_status() == CLOSE_SHAVE_STATUS
        assert await d2.read_parameter_raw("F002") == 1002
        await d1.set_frequency(12.5)
        assert await d2.read_status() == sj.InverterStatus(
            sj.StatusA(3), sj.StatusB(1), sj.StatusC(3)
        )
        if broadcast and n == 1:
            await rig.bus.broadcast.stop()
    totals = rig.stats.transactions
    assert (totals.replies, totals.timeouts, totals.retries) == (4 * ROUNDS, 0, 0)


# -- the claim that makes auto safe: an exact copy of a host frame is never its answer --


def sj300_requests(node: int) -> list[sj3.Request]:
    return [
        rq.run(node, sj.Direction.FORWARD),
        rq.run(node, sj.Direction.STOP),
        rq.set_frequency(node, 0.0),
        rq.set_frequency(node, 40.32),
        rq.set_frequency(node, 9999.99),
        rq.set_terminals(node, sj.InputTerminal.FW),
        rq.read_monitor(node),
        rq.read_status(node),
        rq.read_trip_history(node),
        rq.read_parameter(node, "F002"),
        rq.read_parameter(node, "A004"),
        rq.write_parameter_raw(node, "A004", 500),
        rq.write_parameter_raw(node, "F002", 1),
        rq.initialize(node),
        rq.can_store(node),
        rq.store(node),
        rq.recalculate(node),
    ]


@pytest.mark.parametrize("node", [1, 2, 10, 17, 32])
def test_no_sj300_request_is_an_answer_to_itself(node: int) -> None:
    requests = sj300_requests(node)
    assert {r.command for r in requests} == set(sj3.Command)  # every command
    for request in requests:
        frame = request.frame
        assert 0x06 not in frame  # no ACK, no NAK: see _protocol
        assert 0x15 not in frame
        events = sj3.ReplyParser().feed(frame)
        replies = [e for e in events if not isinstance(e, BadFrame | Discarded)]
        assert not any(sj3.answers(request, reply) for reply in replies), (frame, replies)


def fr700_requests(station: int, options: fr.Fr700LineOptions) -> list[fr.Fr700Request]:
    return [
        frq.read(station, fr.Fr700Instruction.STATUS, options=options),
        frq.read(station, 0x7A, options=options),
        frq.read_parameter(station, 7, options=options),
        frq.write_parameter(station, 7, 50, options=options),
        frq.run(station, sj.Direction.FORWARD, options=options),
        frq.set_frequency(station, 60.0, options=options),
        frq.link_extension(station, 1, options=options),
        frq.reset(station, options=options),
        frq.multi_command(station, 0x0002, 50.0, options=options),
    ]


@pytest.mark.parametrize("terminator", [b"", b"\r", b"\r\n"], ids=["none", "cr", "crlf"])
@pytest.mark.parametrize("wait_field", [True, False], ids=["wait", "nowait"])
def test_no_fr700_request_parses_as_a_drive_frame(terminator: bytes, wait_field: bool) -> None:
    options = fr.Fr700LineOptions(wait_field=wait_field, terminator=terminator)
    for station in (0, 1, 17, 31):
        for request in fr700_requests(station, options):
            assert request.frame[0] == 0x05  # ENQ: no drive frame starts so
            events = fr.Fr700ReplyParser(terminator).feed(request.frame)
            assert all(isinstance(e, Discarded) for e in events), (request.frame, events)


def test_the_fr700_host_ack_is_a_drive_ack_byte_for_byte() -> None:
    """Why a stale expectation must not outlive the next write (rule 3 of _protocol)."""
    host_ack = fr.encode_host_ack(2)
    assert host_ack == fr.encode_ack(2)
    assert fr.Fr700ReplyParser().feed(host_ack) == [fr.Fr700Ack(2)]
    reoutput = fr.encode_reoutput_request(2)
    assert not any(
        isinstance(e, fr.Fr700Ack | fr.Fr700Data | fr.Fr700Nak)
        for e in fr.Fr700ReplyParser().feed(reoutput)
    )


# -- SJ300 ------------------------------------------------------------------------------


@pytest.mark.parametrize("chunking", CHUNKING)
@pytest.mark.parametrize("strip_echo", [True, None], ids=["echo=1", "auto"])
async def test_a_line_that_does_not_echo_loses_no_reply(
    chunking: str, strip_echo: bool | None
) -> None:
    async with sj300_line(
        close_shave, strip_echo=strip_echo, echoing=False, to_host=CHUNKING[chunking]()
    ) as rig:
        await twenty_sj300_transactions(rig)
        stats = rig.stats
        assert (stats.echo_bytes, stats.echo_frames) == (0, 0)
        assert stats.echo_detected is False
        assert (stats.bad_frames, stats.discarded_bytes, stats.stray_frames) == (0, 0, 0)
        # echo=1 counts every echo that did not come; auto just knows the line does not echo
        assert stats.echo_mismatches == (4 * ROUNDS if strip_echo else 0)
        protocol = rig.bus.link.protocol
        assert protocol is not None
        assert protocol._expect_echo is bool(strip_echo)  # auto has gone quiet


@pytest.mark.parametrize("chunking", CHUNKING)
@pytest.mark.parametrize("strip_echo", [True, None], ids=["echo=1", "auto"])
async def test_an_echoing_line_is_stripped_frame_by_frame(
    chunking: str, strip_echo: bool | None
) -> None:
    async with sj300_line(close_shave, strip_echo=strip_echo, to_host=CHUNKING[chunking]()) as rig:
        await twenty_sj300_transactions(rig, broadcast=True)
        written = rig.written()
        assert len(written) == 4 * ROUNDS + 1  # and the broadcast
        stats = rig.stats
        assert stats.echo_frames == len(written)
        assert stats.echo_bytes == sum(map(len, written))
        assert stats.echo_detected is True
        assert stats.echo_mismatches == 0
        assert (stats.bad_frames, stats.discarded_bytes) == (0, 0)
        assert (stats.stray_frames, stats.unsolicited_frames) == (0, 0)
        assert len(rig.parsed()) == 4 * ROUNDS  # the answers, nothing else


@pytest.mark.parametrize("strip_echo", [True, None], ids=["echo=1", "auto"])
async def test_an_echo_in_the_same_chunk_as_the_answer(strip_echo: bool | None) -> None:
    def respond(request: sj3.Request) -> Frames:
        ((delay, answer),) = close_shave(request)
        return [(delay, request.frame + answer)]

    async with sj300_line(respond, strip_echo=strip_echo, echoing=False) as rig:
        await twenty_sj300_transactions(rig)
        assert rig.stats.echo_frames == 4 * ROUNDS
        assert (rig.stats.bad_frames, rig.stats.echo_mismatches) == (0, 0)


@pytest.mark.parametrize("chunking", CHUNKING)
async def test_a_damaged_echo_goes_to_the_parser_whole(chunking: str) -> None:
    """The echo diverges in its BCC: every byte held back reaches the parser, in order."""

    def damage(frame: bytes) -> bytes:
        return frame[:-2] + b"X" + frame[-1:]

    async with sj300_line(
        close_shave, strip_echo=True, damage=damage, to_host=CHUNKING[chunking]()
    ) as rig:
        await twenty_sj300_transactions(rig)
        stats = rig.stats
        assert stats.echo_frames == 0
        assert stats.echo_mismatches == 4 * ROUNDS
        # Each damaged echo is parsed whole, as a frame with a bad BCC: had the
        # held bytes been dropped, only "X\r" would have reached the parser.
        bad = [e for e in rig.parsed() if isinstance(e, BadFrame)]
        assert len(bad) == stats.bad_frames == 4 * ROUNDS
        assert all(e.reason is BadFrameReason.BAD_BCC for e in bad)
        assert [e.body for e in bad[:4]] == [damage(f)[1:-1] for f in rig.written()[:4]]
        assert stats.discarded_bytes == 0


async def test_a_partial_echo_is_held_then_handed_over() -> None:
    """Four bytes of echo, then silence (held until the drain), or then the answer."""

    def respond(request: sj3.Request) -> Frames:
        return [] if request.node == 1 else answer_all(request)

    async with sj300_line(
        respond,
        strip_echo=True,
        damage=lambda frame: frame[:4],
        to_host=bytewise(),
        timing=sj.BusTiming(fixed_timeout_s=0.05),
        retries=0,
    ) as rig:
        with pytest.raises(sj.ReplyTimeoutError):
            await rig.bus.drive(1).read_status()
        assert rig.stats.discarded_bytes == 0  # held back, not yet judged
        # The next transaction drains first: the held bytes go to the parser,
        # which discards them as the partial frame they are.
        assert await rig.bus.drive(2).read_parameter_raw("F002") == 1002
        assert rig.stats.drains == 1
        # Then its own four bytes are held until the answer diverges from the
        # echo; they reach the parser ahead of the answer, which restarts the frame.
        assert rig.stats.discarded_bytes == 4 + 4
        assert rig.stats.echo_frames == 0
        assert rig.stats.echo_mismatches == 2
        assert rig.stats.transactions.replies == 1


async def test_a_quiet_auto_looks_again_when_the_line_starts_echoing() -> None:
    async with sj300_line(strip_echo=None, echoing=False) as rig:
        drive = rig.bus.drive(1)
        for _ in range(5):
            await drive.read_status()
        protocol = rig.bus.link.protocol
        assert protocol is not None
        assert protocol._expect_echo is False  # quiet
        rig.adapters[-1].echoing = True
        for _ in range(5):
            await drive.read_status()
        stats = rig.stats
        # The first echo went to the parser (a bad frame: a request is no reply);
        # that made auto look again, and the next four were stripped.
        assert stats.bad_frames == 1
        assert stats.echo_frames == 4
        assert stats.echo_detected is True
        assert stats.transactions.replies == 10
        assert protocol._expect_echo is True


async def test_late_echoes_queue_on_a_line_known_to_echo() -> None:
    """A device server's latency: the request after a broadcast goes out before its echo is back."""
    timing = sj.BusTiming(margin_s=0.05, broadcast_processing_s=0.0)
    async with sj300_line(strip_echo=None, delay_s=0.01, timing=timing) as rig:
        drive = rig.bus.drive(1)
        await drive.read_status()
        assert rig.stats.echo_detected is True
        await rig.bus.broadcast.stop()
        await drive.read_status()
        await drive.run_forward()
        stats = rig.stats
        assert stats.echo_frames == len(rig.written()) == 4
        assert (stats.bad_frames, stats.echo_mismatches, stats.discarded_bytes) == (0, 0, 0)


async def test_echo_0_never_looks() -> None:
    async with sj300_line(strip_echo=False) as rig:
        await rig.bus.drive(1).read_status()
        stats = rig.stats
        assert stats.echo_detected is None
        assert stats.echo_frames == 0
        assert stats.bad_frames == 1  # the echo, parsed: see test_arbiter


# -- the URL and open_bus ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("query", "echo"),
    [
        ("", None),
        ("?echo=auto", None),
        ("?echo=AUTO", None),
        ("?echo=1", True),
        ("?echo=on", True),
        ("?echo=0", False),
        ("?echo=false", False),
    ],
)
def test_the_url_echo_option(query: str, echo: bool | None) -> None:
    assert sjbus.parse_bus_url(f"tcp://127.0.0.1:4001{query}").echo is echo


def test_a_bad_echo_value_names_the_choices() -> None:
    with pytest.raises(sj.LocalProtocolError, match="echo must be auto, 1 or 0, got 'maybe'"):
        sjbus.parse_bus_url("sim://?echo=maybe")


@pytest.mark.parametrize(
    ("query", "strip_echo", "detected", "mismatches"),
    [
        ("", None, False, 0),  # auto by default
        ("&echo=1", None, False, 1),
        ("&echo=0", None, None, 0),
        ("&echo=1", False, None, 0),  # the argument wins over the URL
        ("&echo=0", True, False, 1),
    ],
)
async def test_open_bus_picks_the_echo_mode(
    query: str, strip_echo: bool | None, detected: bool | None, mismatches: int
) -> None:
    async with sj.open_bus(f"sim://?nodes=1{query}", strip_echo=strip_echo) as bus:
        await bus.drive(1).read_status()
        assert bus.stats.echo_detected is detected
        assert bus.stats.echo_mismatches == mismatches


# -- FR-700 -----------------------------------------------------------------------------

#: Line options: (simulator keyword arguments, URL options).
FR700_LINES: dict[str, tuple[dict[str, Any], dict[str, str]]] = {
    "factory": ({}, {}),
    "crlf-nowait-ack": (
        {"wait_field": False, "terminator": "\r\n"},
        {"wait_field": "0", "terminator": "crlf", "ack": "1"},
    ),
    "bare-ack": ({"terminator": ""}, {"terminator": "none", "ack": "1"}),
}


@contextlib.asynccontextmanager
async def fr700_line(
    line: str,
    *,
    strip_echo: bool | None,
    echoing: bool = True,
    to_host: LineFaults | None = None,
) -> AsyncIterator[EchoRig]:
    """An FR-700 bus to simulated stations 0..3 behind an (optionally) echoing adapter."""
    sim_kwargs, options = FR700_LINES[line]
    sim = Fr700SimulatedBus(range(4), **sim_kwargs)
    rig = EchoRig(bus=None)  # type: ignore[arg-type]  # set below

    def factory(send: Callable[[bytes], None]) -> EchoingAdapter:
        adapter = EchoingAdapter(SimulatorEndpoint(sim, send=send), send, echoing)
        rig.adapters.append(adapter)
        return adapter

    rig.bus = Bus(
        loopback_connector(factory, to_host=to_host),
        description="fr700 echo test",
        line=INSTANT_LINE,
        timing=sj.BusTiming(margin_s=0.05),
        dialect=sjbus.get_dialect("fr700").configure(options),
        trace=rig.trace.append,
        strip_echo=strip_echo,
    )
    async with rig.bus:
        yield rig


async def twenty_fr700_transactions(rig: EchoRig) -> None:
    """Reads (data replies, acknowledged with ack=1) between writes (ACK replies)."""
    for n in range(ROUNDS):
        drive = rig.bus.drive(1 + n % 2)
        await drive.set_frequency(30.0 + n)
        assert await drive.read_set_frequency() == 30.0 + n
        assert not (await drive.read_status()).running
        await drive.stop()
    totals = rig.stats.transactions
    assert (totals.replies, totals.timeouts, totals.retries) == (4 * ROUNDS, 0, 0)


@pytest.mark.parametrize("chunking", CHUNKING)
@pytest.mark.parametrize("line", FR700_LINES)
@pytest.mark.parametrize("strip_echo", [True, None], ids=["echo=1", "auto"])
async def test_fr700_an_echoing_line_is_stripped(
    chunking: str, line: str, strip_echo: bool | None
) -> None:
    async with fr700_line(line, strip_echo=strip_echo, to_host=CHUNKING[chunking]()) as rig:
        await twenty_fr700_transactions(rig)
        written = rig.written()
        acks = 2 * ROUNDS if FR700_LINES[line][1].get("ack") == "1" else 0
        assert len(written) == 4 * ROUNDS + acks  # the host's ACKs are echoed too
        stats = rig.stats
        assert stats.echo_frames == len(written)
        assert stats.echo_bytes == sum(map(len, written))
        assert stats.echo_detected is True
        assert stats.echo_mismatches == 0
        assert (stats.bad_frames, stats.discarded_bytes) == (0, 0)
        assert (stats.stray_frames, stats.unsolicited_frames) == (0, 0)


@pytest.mark.parametrize("chunking", CHUNKING)
@pytest.mark.parametrize("line", FR700_LINES)
@pytest.mark.parametrize("strip_echo", [True, None], ids=["echo=1", "auto"])
async def test_fr700_a_line_that_does_not_echo_loses_no_reply(
    chunking: str, line: str, strip_echo: bool | None
) -> None:
    """With ack=1 the host's ACK is a drive's ACK byte for byte: the next write's
    answer (the stop's ACK) must not be taken for that ACK's echo."""
    async with fr700_line(
        line, strip_echo=strip_echo, echoing=False, to_host=CHUNKING[chunking]()
    ) as rig:
        await twenty_fr700_transactions(rig)
        stats = rig.stats
        assert (stats.echo_frames, stats.echo_bytes) == (0, 0)
        assert stats.echo_detected is False
        assert (stats.bad_frames, stats.discarded_bytes, stats.stray_frames) == (0, 0, 0)
        if strip_echo:
            assert stats.echo_mismatches == len(rig.written())
        else:
            assert stats.echo_mismatches == 0


async def test_fr700_sim_url_with_echo_1_loses_nothing() -> None:
    url = "sim://?protocol=fr700&nodes=0-3&ack=1&echo=1"
    async with sj.open_bus(url, protocol="fr700") as bus:
        for _ in range(10):
            assert not (await bus.drive(2).read_status()).running
            await bus.drive(2).stop()
        assert bus.stats.transactions.replies == 20
        assert bus.stats.transactions.timeouts == 0
        assert bus.stats.echo_frames == 0
