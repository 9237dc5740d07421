"""Fault hooks: what a test does to the replies on the simulated line.

Faults act on the drive's *reply*, after the drive has executed the
request: a dropped reply to a write means the write happened and the host
never heard of it, which is the case a host must survive. A silenced node
is different: it is off the line, hears nothing and executes nothing.

One-shot faults count the node's next replies, each kind on its own: with
``drop_next(1)`` and ``delay_next(1, 0.5)`` pending, the next reply is
dropped and that also uses up the delay.

A drive answers in order: a reply it was made to hold back holds back every
later reply of that node too (it goes out no sooner than the held one), as
a drive busy with a slow answer does. Without that, a sync request sent
after a time-out would be answered before the late reply it is there to
flush, which no real drive does. :meth:`Faults.clear` ends the faults, not
the replies already held: those still go out in order.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from ..wire import LocalProtocolError

__all__ = ["FaultedReply", "Faults"]


def _check_node(node: int, nodes: range) -> None:
    if isinstance(node, bool) or not isinstance(node, int) or node not in nodes:
        raise LocalProtocolError(f"node must be {nodes.start}..{nodes.stop - 1}, got {node!r}")


def _check_count(count: int) -> None:
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise LocalProtocolError(f"count must be a positive int, got {count!r}")


def _check_seconds(seconds: float) -> None:
    if not seconds >= 0:  # also refuses NaN
        raise LocalProtocolError(f"a delay is >= 0 seconds, got {seconds!r}")


def corrupt(frame: bytes) -> bytes:
    """Flip the lowest bit of the byte before the BCC, so the BCC no longer matches.

    That byte is ACK, a NAK code digit or a data character: flipping its
    lowest bit never makes an STX or a CR, so the frame keeps its shape and
    only its check fails.
    """
    at = len(frame) - 4
    return frame[:at] + bytes((frame[at] ^ 0x01,)) + frame[at + 1 :]


@dataclass(frozen=True, slots=True)
class FaultedReply:
    """A reply after the faults: its extra delay, its bytes, and what was done to it."""

    extra_delay_s: float
    data: bytes
    corrupted: bool
    delayed: bool


class Faults:
    """Hooks to drop, delay or corrupt replies, make a node late, or take it off the line.

    Args:
        nodes: the addresses a fault may name (default 1..32, SJ300's nodes; each
            protocol's simulator passes its own: FR-700 stations 0..31).
        corrupt: how :meth:`corrupt_next` damages a reply frame so its check fails
            (the protocol's frames differ: see :func:`corrupt` for SJ300's).
    """

    def __init__(
        self,
        *,
        nodes: range = range(1, 33),
        corrupt: Callable[[bytes], bytes] = corrupt,
    ) -> None:
        self._nodes = nodes
        self._corrupt_frame = corrupt
        self._drop: dict[int, int] = {}
        self._corrupt: dict[int, int] = {}
        self._delay: dict[int, deque[float]] = {}
        self._late: dict[int, float] = {}
        self._silent: set[int] = set()
        #: When each node's latest held-back reply goes out (see the module docstring).
        self._held: dict[int, float] = {}

    def drop_next(self, node: int, count: int = 1) -> None:
        """Lose the next *count* replies of *node* (the drive still executes the requests)."""
        _check_node(node, self._nodes)
        _check_count(count)
        self._drop[node] = self._drop.get(node, 0) + count

    def delay_next(self, node: int, seconds: float, count: int = 1) -> None:
        """Hold the next *count* replies of *node* for *seconds* more."""
        _check_node(node, self._nodes)
        _check_count(count)
        _check_seconds(seconds)
        self._delay.setdefault(node, deque()).extend([seconds] * count)

    def corrupt_next(self, node: int, count: int = 1) -> None:
        """Damage the next *count* replies of *node* so their BCC fails (see :func:`corrupt`)."""
        _check_node(node, self._nodes)
        _check_count(count)
        self._corrupt[node] = self._corrupt.get(node, 0) + count

    def late(self, node: int, seconds: float) -> None:
        """Delay every reply of *node* by *seconds* from now on (0 clears)."""
        _check_node(node, self._nodes)
        _check_seconds(seconds)
        if seconds:
            self._late[node] = seconds
        else:
            self._late.pop(node, None)

    def silence(self, node: int, silent: bool = True) -> None:
        """Take *node* off the line (it hears and answers nothing), or put it back."""
        _check_node(node, self._nodes)
        if silent:
            self._silent.add(node)
        else:
            self._silent.discard(node)

    def is_silent(self, node: int) -> bool:
        """True while *node* is off the line."""
        return node in self._silent

    def clear(self) -> None:
        """Remove every fault."""
        self._drop.clear()
        self._corrupt.clear()
        self._delay.clear()
        self._late.clear()
        self._silent.clear()

    def pending(self, node: int) -> bool:
        """True when a fault may act on *node*'s next reply.

        When False, :meth:`apply` would pass the reply on untouched, so a
        caller may skip it.
        """
        return (
            node in self._drop
            or node in self._corrupt
            or node in self._delay
            or node in self._late
            or node in self._held
        )

    def held_until(self) -> float:
        """When the last reply held back by a delay goes out (-inf when none is held)."""
        return max(self._held.values(), default=-math.inf)

    def apply(self, node: int, frame: bytes, due: float = 0.0) -> FaultedReply | None:
        """Consume *node*'s pending one-shot faults for one reply; None when it is dropped.

        Args:
            due: when the reply would go out without faults, on the caller's
                clock: a reply is held behind an earlier delayed one until then.
        """
        delays = self._delay.get(node)
        extra = 0.0
        if delays is not None:
            extra = delays.popleft()
            if not delays:
                del self._delay[node]  # so that pending() is False again
        delayed = bool(extra)
        extra += self._late.get(node, 0.0)
        corrupted = _take(self._corrupt, node)
        if _take(self._drop, node):
            return None
        held = self._held.get(node)
        if held is not None:
            if held > due + extra:
                extra = held - due  # behind the held reply, in order
            elif not extra:
                del self._held[node]  # the held reply is out: the node is in order again
        if extra:
            self._held[node] = due + extra
        damaged = self._corrupt_frame(frame) if corrupted else frame
        return FaultedReply(extra, damaged, corrupted, delayed)


def _take(counts: dict[int, int], node: int) -> bool:
    """Use up one pending fault of *node*; False if none was pending."""
    left = counts.get(node, 0)
    if not left:
        return False
    if left == 1:
        del counts[node]
    else:
        counts[node] = left - 1
    return True
