"""The soak's fault model: what the line and the drives do wrong, and how often.

Two sources, both counted by kind:

- :class:`FrameFaults`, a :class:`~sj300_async.transports.LineFaults` for one
  direction of the loopback line. On top of the stock fragmentation and
  delays it damages whole frames: one byte corrupted, dropped, inserted or
  duplicated; the content made invalid with the BCC recomputed so that it
  still matches (letters where digits belong, an impossible node, a wrong
  length); and, towards the host, valid frames from nodes nobody addresses
  (another segment, a misconfigured drive) slipped in before or after a reply;
  and whole replies delivered twice, the copy in its own chunk a few
  milliseconds after the original (a bridge that retransmits).
- :class:`DriveChaos`, which drives the simulator's own hooks: replies
  dropped, corrupted, delayed past the time-out (a little, or up to 5
  time-outs: the drive answers in order, so its later replies wait behind),
  a node made late or taken off the line for a while, drives tripped.

Why at most one byte fault per frame. The SJ300's block check is an XOR:
it catches every single corrupted, dropped, inserted or duplicated byte,
but two faults in one frame cancel out whenever they hit the same bit
column (a duplicated '0' and a dropped '0' elsewhere turn ``00001500`` into
``00000150`` with the same BCC). No host can detect that; the protocol has
no stronger check. The soak therefore proves the library's promise over
the faults the protocol can detect, and :mod:`test_rel_bcc_limits` measures
how often independent double faults slip through, so the limit is a
published figure rather than a surprise.

Soundness is checked, not assumed: every damaged frame is re-parsed with a
fresh parser before it goes on the line, and a fault that would leave a
valid frame other than the original (or a planted stray) is not applied but
counted as ``unsound_skipped`` — a fault the protocol cannot see is not a
test of the library.
"""

from __future__ import annotations

import functools
import operator
import random
from collections.abc import Callable
from dataclasses import dataclass, field

from sj300_async import sj300 as sj3
from sj300_async import wire
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.transports import LineFaults

STX = 0x02
CR = 0x0D
BYTE_FAULTS = ("corrupted", "dropped", "inserted", "duplicated")
# Characters that are never valid content anywhere in a frame body.
_NEVER_VALID = b"GHJKLMNPQRSTUVWXYZ!#$%&*+/:;<=>?@"


def xor_bcc(body: bytes) -> bytes:
    """The reference BCC (written out here, not the library's)."""
    return b"%02X" % functools.reduce(operator.xor, body, 0)


def frame(body: bytes) -> bytes:
    return b"\x02" + body + xor_bcc(body) + b"\r"


def split_frame(data: bytes) -> bytes | None:
    """The body of *data* if it is exactly one STX..CR frame with a matching BCC."""
    if len(data) < 4 or data[0] != STX or data[-1] != CR:
        return None
    body = data[1:-3]
    if STX in body or CR in body or xor_bcc(body) != data[-3:-1].upper():
        return None
    return body


def stray_frame(rng: random.Random, nodes: tuple[int, ...]) -> bytes:
    """A valid reply from a node that nobody on this bus addresses."""
    node = b"%02d" % rng.choice(nodes)
    kind = rng.randrange(5)
    if kind == 0:
        return frame(node + b"\x06")
    if kind == 1:
        return frame(node + b"\x15" + b"%02d" % rng.choice((1, 2, 5, 11, 16)))
    if kind == 2:
        return frame(node + b"\x06" + b"%08d" % rng.randrange(10**8))
    if kind == 3:
        return frame(node + b"%02d%02d%02d00" % (3, 1, 3))
    return frame(node + b"%08d" % rng.randrange(10**8) * 13)


@dataclass
class FrameFaults(LineFaults):
    """Frame-level faults for one direction of the loopback line (see the module docstring).

    The stock per-byte rates of LineFaults stay at zero here: byte faults
    come one per frame, at ``byte_fault_rate`` per frame.
    """

    #: Per frame: one byte fault, of a kind drawn from BYTE_FAULTS.
    byte_fault_rate: float = 0.0
    #: Per frame: invalid content under a matching BCC.
    garble_rate: float = 0.0
    #: Per frame (towards the host): a valid frame from a node in ``stray_nodes``.
    stray_rate: float = 0.0
    stray_nodes: tuple[int, ...] = tuple(range(20, 33))
    #: Judges whether a damaged frame is still valid: a ReplyParser or RequestParser factory.
    parser_factory: Callable[[], sj3.ReplyParser | sj3.RequestParser] = sj3.ReplyParser
    #: Per frame (towards the host): the undamaged frame again, in its own chunk,
    #: ``duplicate_delay_s`` after the original. Detectable only while the copy
    #: arrives before the plausibility floor of the next request (so: on a line
    #: with a speed; see docs/RELIABILITY.md).
    duplicate_rate: float = 0.0
    duplicate_delay_s: tuple[float, float] = (0.001, 0.005)

    def apply(self, data: bytes) -> list[tuple[float, bytes]]:
        pieces = super().apply(data)
        if self.duplicate_rate and split_frame(data) and self.rng.random() < self.duplicate_rate:
            after = pieces[-1][0] if pieces else 0.0
            pieces.append((after + self.rng.uniform(*self.duplicate_delay_s), data))
            self.counts["duplicated_replies"] += 1
        return pieces

    def mangle(self, data: bytes) -> bytes:
        body = split_frame(data)
        rng = self.rng
        out = data
        if body is not None:  # never add a second fault to a frame damaged already
            if self.garble_rate and rng.random() < self.garble_rate:
                out = self._garble(data, body)
            elif self.byte_fault_rate and rng.random() < self.byte_fault_rate:
                out = self._byte_fault(data)
        if self.stray_rate and rng.random() < self.stray_rate:
            stray = stray_frame(rng, self.stray_nodes)
            out = stray + out if rng.random() < 0.5 else out + stray
            self.counts["stray_frames"] += 1
        return out

    def stop(self) -> None:
        """Stop injecting (the counts stay)."""
        self.byte_fault_rate = self.garble_rate = self.stray_rate = self.duplicate_rate = 0.0
        self.delay_rate = 0.0
        self.fragment_max = 0

    # -- the faults ------------------------------------------------------------

    def _byte_fault(self, data: bytes) -> bytes:
        rng = self.rng
        kind = rng.choice(BYTE_FAULTS)
        at = rng.randrange(len(data))
        if kind == "corrupted":
            damaged = data[:at] + bytes((data[at] ^ (1 << rng.randrange(8)),)) + data[at + 1 :]
        elif kind == "dropped":
            damaged = data[:at] + data[at + 1 :]
        elif kind == "inserted":
            damaged = data[:at] + bytes((rng.randrange(256),)) + data[at:]
        else:
            damaged = data[:at] + data[at : at + 1] + data[at:]
        return self._if_sound(data, damaged, kind)

    def _garble(self, data: bytes, body: bytes) -> bytes:
        rng = self.rng
        for _ in range(8):
            kind = rng.randrange(3)
            chars = bytearray(body)
            if kind == 0:  # a letter (or sign) where the protocol wants something else
                chars[rng.randrange(len(chars))] = rng.choice(_NEVER_VALID)
            elif kind == 1:  # an address no drive can have
                chars[0:2] = rng.choice((b"00", b"99", b"0A", b"3 ", b"-1"))
            elif rng.random() < 0.5 and len(chars) > 3:  # a length no frame has
                del chars[rng.randrange(2, len(chars))]
            else:
                chars.insert(rng.randrange(2, len(chars) + 1), rng.choice(b"0123456789"))
            damaged = frame(bytes(chars))
            if self._valid_frames(damaged) == []:
                self.counts["bcc_valid_garbage"] += 1
                return damaged
        return data  # every attempt stayed valid (cannot happen for our shapes): leave it

    def _if_sound(self, original: bytes, damaged: bytes, kind: str) -> bytes:
        allowed = self._valid_frames(original)
        if all(f in allowed for f in self._valid_frames(damaged)):
            self.counts[kind] += 1
            return damaged
        self.counts["unsound_skipped"] += 1
        return original

    def _valid_frames(self, data: bytes) -> list[object]:
        events = self.parser_factory().feed(data)
        return [  # a request as what it asks: the case of its BCC does not matter
            (e.node, e.command, e.data) if isinstance(e, sj3.Request) else e
            for e in events
            if not isinstance(e, wire.BadFrame | wire.Discarded)
        ]


@dataclass
class DriveChaos:
    """Applies the simulator's fault hooks at random (see the module docstring).

    Two kinds of delay past the time-out: a little (:meth:`late_delay`,
    1.05..1.35 time-outs, also every reply of a late episode) and very late
    (:meth:`very_late_delay`, 2.2..5 time-outs). The bus promises to catch a
    reply up to 5 time-outs late from a drive that answers in order (its
    resync; see docs/RELIABILITY.md), so no delay goes past that: a very late
    reply is never drawn during a late episode of its node.
    """

    sim: SimulatedBus
    rng: random.Random
    timeout_s: float
    #: Per request: probability of one one-shot fault on a random node.
    rate: float = 0.01
    #: The one-shot faults, drawn with equal chance (repeat a kind to weigh it more).
    kinds: tuple[str, ...] = ("drop_next", "corrupt_next", "delay_next", "very_late_next", "trip")
    counts: dict[str, int] = field(default_factory=dict)
    _episode: tuple[str, int] | None = None

    def _count(self, kind: str) -> None:
        self.counts[kind] = self.counts.get(kind, 0) + 1

    def late_delay(self) -> float:
        """A delay past the time-out that still ends well before twice the time-out."""
        return self.timeout_s * self.rng.uniform(1.05, 1.35)

    def very_late_delay(self) -> float:
        """A delay of 2.2..5 time-outs: the adversary's very late replies (issue 14)."""
        return self.timeout_s * self.rng.uniform(2.2, 5.0)

    def maybe(self, now: float) -> None:
        """Called once per request: perhaps damage a drive's next reply, or trip it."""
        rng = self.rng
        if rng.random() >= self.rate:
            return
        node = rng.choice(sorted(self.sim.drives))
        faults = self.sim.faults
        kind = rng.choice(self.kinds)
        if kind in ("delay_next", "very_late_next") and self._episode == ("late", node):
            kind = "drop_next"  # late plus delayed could pass the 5 time-outs promised
        if kind == "drop_next":
            faults.drop_next(node)
        elif kind == "corrupt_next":
            faults.corrupt_next(node)
        elif kind == "delay_next":
            faults.delay_next(node, self.late_delay())
        elif kind == "very_late_next":
            faults.delay_next(node, self.very_late_delay())
        elif not self.sim.drives[node].trip(rng.choice((1, 5, 7, 9, 12, 21)), now=now):
            return  # already tripped: nothing happened
        self._count(kind)

    def toggle_episode(self) -> None:
        """End the current episode, or start one: a node late past its time-out, or off the line."""
        faults = self.sim.faults
        if self._episode is not None:
            kind, node = self._episode
            if kind == "late":
                faults.late(node, 0)
            else:
                faults.silence(node, False)
            self._episode = None
            return
        node = self.rng.choice(sorted(self.sim.drives))
        if self.rng.random() < 0.5:
            faults.late(node, self.late_delay())
            self._episode = ("late", node)
        else:
            faults.silence(node)
            self._episode = ("silenced", node)
        self._count(f"{self._episode[0]}_episodes")

    def stop(self) -> None:
        """End every fault: episodes, and one-shot faults still pending."""
        if self._episode is not None:
            self.toggle_episode()
        self.sim.faults.clear()
