"""What every fuzz input must satisfy, and where inputs come from (shared by all fuzzers).

:func:`check_input` runs one input — arbitrary bytes cut into arbitrary
chunks — through the three things that read bytes from a line: the host's
ReplyParser, the drive-side RequestParser, and a whole SimulatedBus. It
raises AssertionError on the first broken promise:

- only documented events come out (replies, BadFrame, Discarded; requests);
- a parser never holds more than its longest legal frame (444 / 22 bytes);
- every byte fed is accounted for: in a frame, a bad frame, a discarded
  run, or the partial frame that ``reset()`` hands back;
- the parser's counters agree with the events;
- the events do not depend on how the stream was cut;
- every reply decodes to its typed payload or raises RemoteProtocolError;
- the simulator only ever answers with valid reply frames from its own nodes.

:class:`Mutator` makes inputs for the plain fuzz loop: valid frames of both
directions, spliced, mutated, truncated, mixed with noise.
"""

from __future__ import annotations

import itertools
import random
import time
from dataclasses import dataclass

import sj300_async as sj
from sj300_async import sj300 as sj3
from sj300_async import wire
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.sj300._constants import MAX_REPLY_BODY, MAX_REQUEST_BODY

REPLY_EVENTS = (sj3.AckReply, sj3.AckDataReply, sj3.DataReply, sj3.NakReply)
SIM_NODES = (1, 2, 3, 31)
_DECODERS = {
    (sj3.DataReply, 8): sj3.decode_status,
    (sj3.DataReply, 104): sj3.decode_monitor,
    (sj3.DataReply, 440): sj3.decode_trip_history,
    (sj3.AckDataReply, 8): sj3.decode_parameter_value,
    (sj3.AckDataReply, 2): sj3.decode_can_store,
}


def chunks(data: bytes, cuts: list[int]) -> list[bytes]:
    """*data* cut at the given positions (taken modulo its length, in order)."""
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


def _merged(events: list[object]) -> list[object]:
    """Adjacent Discarded events of one reason merged (chunking may split a run)."""
    out: list[object] = []
    for event in events:
        last = out[-1] if out else None
        if (
            isinstance(event, wire.Discarded)
            and isinstance(last, wire.Discarded)
            and last.reason is event.reason
        ):
            out[-1] = wire.Discarded(event.reason, last.data + event.data)
        else:
            out.append(event)
    return out


def _length(event: object) -> int:
    """Bytes of the stream an event stands for."""
    if isinstance(event, wire.Discarded):
        return len(event.data)
    if isinstance(event, wire.BadFrame):
        return len(event.body) + 2
    if isinstance(event, sj3.Request):
        return len(event.frame)
    return len(sj3.encode_reply(event))  # type: ignore[arg-type]


def _feed(
    parser: sj3.ReplyParser | sj3.RequestParser,
    pieces: list[bytes],
    allowed: tuple[type, ...],
    limit: int,
) -> list[object]:
    events: list[object] = []
    for piece in pieces:
        for event in parser.feed(piece):
            assert isinstance(event, allowed), f"undocumented event {event!r}"
            events.append(event)
        assert parser.buffered <= limit, f"{parser.buffered} bytes buffered > {limit}"
    events.extend(parser.reset())
    assert parser.buffered == 0
    return events


def check_stream(data: bytes, cuts: list[int], *, requests: bool = False) -> list[object]:
    """Run *data* through a fresh parser (reply or request), whole and in chunks."""
    make: type[sj3.RequestParser | sj3.ReplyParser]
    if requests:
        make, limit = sj3.RequestParser, MAX_REQUEST_BODY
        allowed: tuple[type, ...] = (sj3.Request, wire.BadFrame, wire.Discarded)
    else:
        make, limit = sj3.ReplyParser, MAX_REPLY_BODY
        allowed = (*REPLY_EVENTS, wire.BadFrame, wire.Discarded)
    parser = make()
    events = _feed(parser, chunks(data, cuts), allowed, limit)
    assert sum(map(_length, events)) == len(data), "bytes not accounted for"
    frames = [e for e in events if not isinstance(e, wire.BadFrame | wire.Discarded)]
    stats = parser.stats
    assert stats.frames == len(frames)
    assert stats.bad_frames == sum(isinstance(e, wire.BadFrame) for e in events)
    discarded = sum(len(e.data) for e in events if isinstance(e, wire.Discarded))
    assert stats.discarded_bytes == discarded
    whole = _feed(make(), [data], allowed, limit)
    assert _merged(events) == _merged(whole), "events depend on the chunking"
    return events


def check_decoders(events: list[object]) -> None:
    """Every reply decodes, or raises RemoteProtocolError; nothing else."""
    for event in events:
        decode = _DECODERS.get((type(event), len(getattr(event, "data", b""))))
        if decode is None:
            continue
        try:
            decode(event.data)  # type: ignore[attr-defined]
        except sj.RemoteProtocolError:
            pass


def check_simulator(data: bytes, cuts: list[int]) -> int:
    """A simulated line answers arbitrary bytes with valid replies only; returns their number."""
    sim = SimulatedBus(SIM_NODES)
    answers = 0
    now = 0.0
    for piece in chunks(data, cuts):
        now += 0.001
        for transmission in sim.receive(piece, now):
            events = sj3.ReplyParser().feed(transmission.data)
            assert len(events) == 1, f"not one frame: {transmission.data!r}"
            assert isinstance(events[0], REPLY_EVENTS), f"invalid reply {events[0]!r}"
            assert events[0].node in SIM_NODES
            assert transmission.delay_s >= 0
            answers += 1
        assert sim._parser.buffered <= MAX_REQUEST_BODY
    return answers


def check_input(data: bytes, cuts: list[int]) -> None:
    """Every promise above, for one input."""
    check_decoders(check_stream(data, cuts))
    check_stream(data, cuts, requests=True)
    check_simulator(data, cuts)


class Mutator:
    """Inputs for the plain fuzz loop (see the module docstring). Deterministic per seed."""

    def __init__(self, seed: int) -> None:
        self.rng = random.Random(seed)
        rng = self.rng
        self.frames = [*self._replies(rng), *self._requests()]

    @staticmethod
    def _replies(rng: random.Random) -> list[bytes]:
        frames = []
        for node in (1, 2, 9, 31, 32):
            frames.append(sj3.encode_reply(sj3.AckReply(node)))
            frames.append(sj3.encode_reply(sj3.AckDataReply(node, b"%08d" % rng.randrange(10**8))))
            frames.append(sj3.encode_reply(sj3.AckDataReply(node, b"01")))
            frames.append(sj3.encode_reply(sj3.NakReply(node, sj.NakCode(16))))
            frames.append(sj3.encode_reply(sj3.DataReply(node, b"03010300")))
            monitor = b"".join(b"%08d" % rng.randrange(10**4) for _ in range(13))
            frames.append(sj3.encode_reply(sj3.DataReply(node, monitor)))
            frames.append(sj3.encode_reply(sj3.DataReply(node, b"%08d" % 3 + b"00000000" * 54)))
        return frames

    @staticmethod
    def _requests() -> list[bytes]:
        rq = sj3.requests
        frames = []
        for node in (1, 2, 31, sj3.BROADCAST):
            frames += [rq.run(node, sj.Direction.FORWARD).frame, rq.set_frequency(node, 12.5).frame]
            frames += [rq.set_terminals(node, sj.InputTerminal.RS).frame]
            frames += [rq.write_parameter_raw(node, "A020", 1234).frame, rq.initialize(node).frame]
            frames += [rq.store(node).frame]
            if node != sj3.BROADCAST:
                frames += [rq.read_status(node).frame, rq.read_monitor(node).frame]
                frames += [rq.read_trip_history(node).frame, rq.read_parameter(node, "C072").frame]
                frames += [rq.can_store(node).frame, rq.recalculate(node).frame]
        return frames

    def next(self) -> tuple[bytes, list[int]]:
        """One input and its cut points."""
        rng = self.rng
        style = rng.random()
        if style < 0.15:
            data = rng.randbytes(rng.randrange(0, 600))
        elif style < 0.3:
            alphabet = b"\x02\r\x06\x150123456789ABCDEFabcdef-FG \x00\xff"
            data = bytes(rng.choice(alphabet) for _ in range(rng.randrange(0, 300)))
        else:
            parts = [rng.choice(self.frames) for _ in range(rng.randint(1, 6))]
            data = self.mutate(b"".join(parts))
        cuts = [rng.randrange(len(data) + 1) for _ in range(rng.randint(0, 8))]
        return data, cuts

    def mutate(self, data: bytes) -> bytes:
        rng = self.rng
        out = bytearray(data)
        for _ in range(rng.choice((0, 1, 1, 2, 3, 8))):
            if not out:
                break
            at = rng.randrange(len(out))
            kind = rng.randrange(6)
            if kind == 0:
                out[at] ^= 1 << rng.randrange(8)
            elif kind == 1:
                del out[at]
            elif kind == 2:
                out.insert(at, rng.choice((0x02, 0x0D, 0x06, 0x15, rng.randrange(256))))
            elif kind == 3:
                out[at:at] = out[at : at + rng.randint(1, 20)]
            elif kind == 4:
                del out[at:]
            else:
                out[at] = rng.choice(b"0123456789")
        return bytes(out)


@dataclass(frozen=True)
class LoopResult:
    """What one run of :func:`mutation_loop` found."""

    #: The first broken promise, with the input that broke it (None: all kept).
    failure: str | None
    bytes: int = 0
    slowest_s: float = 0.0


def mutation_loop(seed: int, inputs: int) -> LoopResult:
    """Run *inputs* inputs of ``Mutator(seed)`` through :func:`check_input`.

    A broken promise comes back as ``failure`` rather than as an exception, so
    the loop can run in a worker process.
    """
    mutator = Mutator(seed)
    slowest = 0.0
    total = 0
    for _ in range(inputs):
        data, cuts = mutator.next()
        begin = time.perf_counter()
        try:
            check_input(data, cuts)
        except AssertionError as exc:
            return LoopResult(f"input {data!r} cut at {cuts}: {exc}")
        slowest = max(slowest, time.perf_counter() - begin)
        total += len(data)
    return LoopResult(None, total, slowest)
