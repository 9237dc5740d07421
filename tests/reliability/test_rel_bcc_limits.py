"""What the SJ300's XOR block check can and cannot catch: the limit of any host's guarantee.

Every single byte fault — one bit flipped, a byte dropped, inserted or
duplicated — in any reply a drive sends and any request the host sends is
detected: tried exhaustively here on the simulator's real frames. Two faults
in one frame can cancel out; the second test measures how often, so that
docs/RELIABILITY.md can state the residual risk of the protocol itself (the
fault soak therefore injects at most one byte fault per frame; see
rel_faults.py).
"""

from __future__ import annotations

import random
from collections import Counter
from collections.abc import Callable, Iterator
from typing import Any

import pytest

import sj300_async as sj
from sj300_async import sj300 as sj3
from sj300_async import wire
from sj300_async.simulator.sj300 import SimulatedBus

from .rel_sizes import Sizes

pytestmark = pytest.mark.soak

rq = sj3.requests


def _requests(node: int) -> list[sj3.Request]:
    return [
        rq.read_status(node),
        rq.read_monitor(node),
        rq.read_trip_history(node),
        rq.read_parameter(node, "A020"),
        rq.write_parameter_raw(node, "A020", node * 1000 + 17),
        rq.set_frequency(node, 8.5),
        rq.can_store(node),
        rq.run(node, sj.Direction.FORWARD),
        rq.read_parameter(node, "P999"),  # NAK 16
    ]


def _frames() -> tuple[list[bytes], list[bytes]]:
    """(replies, requests): what really crosses the line, from the simulator."""
    sim = SimulatedBus(range(1, 9))
    requests = [r for node in (1, 5, 8) for r in _requests(node)]
    replies = [sim.receive(r.frame, 1.0)[0].data for r in requests]
    return replies, [r.frame for r in requests]


def _valid(make: Callable[[], Any], data: bytes) -> list[object]:
    """The valid frames in *data*; a request as what it asks (its BCC's case does not matter)."""
    return [
        (e.node, e.command, e.data) if isinstance(e, sj3.Request) else e
        for e in make().feed(data)
        if not isinstance(e, wire.BadFrame | wire.Discarded)
    ]


def _single_faults(frame: bytes, insert_values: bytes) -> Iterator[tuple[str, bytes]]:
    for at in range(len(frame)):
        byte = frame[at : at + 1]
        for bit in range(8):
            yield "corrupted", frame[:at] + bytes((frame[at] ^ 1 << bit,)) + frame[at + 1 :]
        yield "dropped", frame[:at] + frame[at + 1 :]
        yield "duplicated", frame[:at] + byte + frame[at:]
        for value in insert_values:
            yield "inserted", frame[:at] + bytes((value,)) + frame[at:]


def _judge(make: Callable[[], Any], original: bytes, damaged: bytes) -> str:
    found = _valid(make, damaged)
    if not found:
        return "detected"
    if found == _valid(make, original):
        return "harmless"  # noise before the STX, a lower-case BCC...
    return "undetected"


def test_every_single_byte_fault_is_detected(soak: bool, soak_figures: dict[str, Any]) -> None:
    # The long form inserts every byte value; the short form the ones that matter most.
    values = bytes(range(256)) if soak else b"\x00\x02\x06\x0d\x15\xff09AFaf-GZ "
    replies, requests = _frames()
    outcomes: Counter[str] = Counter()
    escaped = []
    for frames, make in ((replies, sj3.ReplyParser), (requests, sj3.RequestParser)):
        for frame in frames:
            for kind, damaged in _single_faults(frame, values):
                verdict = _judge(make, frame, damaged)
                outcomes[verdict] += 1
                if verdict == "undetected":
                    escaped.append(f"{kind}: {frame!r} -> {damaged!r}")
    soak_figures["bcc_single_faults"] = dict(outcomes)
    assert escaped == []


def test_double_faults_can_escape_the_bcc(sizes: Sizes, soak_figures: dict[str, Any]) -> None:
    """Not a library property: the protocol's. Measured, so the docs can quote it."""
    rng = random.Random(6)
    replies, requests = _frames()

    def fault(frame: bytes) -> bytes:
        at = rng.randrange(len(frame))
        kind = rng.randrange(4)
        if kind == 0:
            return frame[:at] + bytes((frame[at] ^ 1 << rng.randrange(8),)) + frame[at + 1 :]
        if kind == 1:
            return frame[:at] + frame[at + 1 :]
        if kind == 2:
            return frame[:at] + bytes((rng.randrange(256),)) + frame[at:]
        return frame[:at] + frame[at : at + 1] + frame[at:]

    figures = {}
    samples = sizes.fuzz_inputs // 4
    for name, frames, make in (
        ("replies", replies, sj3.ReplyParser),
        ("requests", requests, sj3.RequestParser),
    ):
        outcomes: Counter[str] = Counter()
        for _ in range(samples):
            frame = rng.choice(frames)
            outcomes[_judge(make, frame, fault(fault(frame)))] += 1
        figures[name] = {
            **outcomes,
            "undetected_percent": round(100 * outcomes["undetected"] / samples, 3),
        }
    soak_figures["bcc_double_faults"] = {"samples_each": samples, **figures}
    # The limit is real: if this ever reads 0, the docs' explanation of the fault model is wrong.
    assert figures["replies"]["undetected"] > 0


@pytest.mark.parametrize("node", [1, 32])
def test_a_reply_from_the_wrong_node_is_never_taken(node: int) -> None:
    """Corrupting the node digits of a reply never yields another node's valid reply."""
    replies, _ = _frames()
    for frame in replies:
        for bit in range(8):
            for at in (1, 2):
                damaged = frame[:at] + bytes((frame[at] ^ 1 << bit,)) + frame[at + 1 :]
                assert _judge(sj3.ReplyParser, frame, damaged) != "undetected"
