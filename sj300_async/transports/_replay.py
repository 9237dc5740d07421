"""Replay: a capture plays the drives' part, so a user's capture becomes a test.

``replay://PATH.pcapng`` answers each request the host writes with what the
capture recorded after the same request: every inbound packet up to the
next outbound one (replies, echo, noise and broken frames alike), each as
long after the write as it came in the capture. A request that got no
answer in the capture gets none now, so the host times out as it did; a
reply that came late comes late again.

Which recorded request. The host's requests are looked up in the capture's
order: from just after the last one matched to the end, then from the start
(a command run twice, or run in another order, still finds its answers).
The match is byte for byte, so the node, the command and the data must be
those of the capture.

A request the capture does not hold is refused at once with a
:class:`ReplayMismatchError` (a ``TransportError``: never retried), raised
by the write, naming the request and what the capture holds; the replay
stays open for the next request. The peer runs inside the loopback
transport, which hands a write to it synchronously (replay sets no line
faults, so nothing is ever queued ahead of a write), so the error reaches
the request that caused it.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..wire import PacketDirection, PcapngCapture, TransportError
from ._loopback import loopback_connector

__all__ = ["ReplayMismatchError", "ReplayScript", "replay_connector"]


class ReplayMismatchError(TransportError):
    """The host wrote a frame the capture being replayed does not hold."""


@dataclass(frozen=True, slots=True)
class _Exchange:
    request: bytes
    #: (seconds after the request, bytes) of what came in before the next request.
    answers: tuple[tuple[float, bytes], ...]


class ReplayScript:
    """One interface of a capture as request → answers exchanges, in capture order.

    Args:
        describe: names a written frame in the refusal's message (the
            protocol's summary of it); the hex dump follows it.
    """

    def __init__(
        self,
        capture: PcapngCapture,
        interface: int,
        *,
        name: str,
        describe: Callable[[bytes], str] | None = None,
    ) -> None:
        self.name = name
        self._describe = describe
        exchanges: list[_Exchange] = []
        request: tuple[int, bytes] | None = None
        answers: list[tuple[float, bytes]] = []
        for packet in capture.packets:
            if packet.interface != interface:
                continue
            if packet.direction is PacketDirection.OUTBOUND:
                if request is not None:
                    exchanges.append(_Exchange(request[1], tuple(answers)))
                request, answers = (packet.timestamp_us, packet.data), []
            elif request is not None:  # what came in before the first write is not an answer
                answers.append(((packet.timestamp_us - request[0]) / 1e6, packet.data))
        if request is not None:
            exchanges.append(_Exchange(request[1], tuple(answers)))
        self._exchanges = exchanges
        self._next = 0

    @property
    def requests(self) -> int:
        """How many frames the host wrote in the capture."""
        return len(self._exchanges)

    def answer(self, frame: bytes) -> tuple[tuple[float, bytes], ...]:
        """What the capture recorded after *frame* (see the module docstring).

        Raises:
            ReplayMismatchError: the capture never saw the host write *frame*.
        """
        exchanges = self._exchanges
        count = len(exchanges)
        for step in range(count):
            index = (self._next + step) % count
            if exchanges[index].request == frame:
                self._next = index + 1
                return exchanges[index].answers
        raise ReplayMismatchError(self._refusal(frame))

    def _refusal(self, frame: bytes) -> str:
        what = self._describe(frame) if self._describe is not None else "the request"
        held = sorted({self._name_of(exchange.request) for exchange in self._exchanges})
        shown = "; ".join(held[:8]) + (f"; and {len(held) - 8} more" if len(held) > 8 else "")
        return (
            f"{self.name}: the capture holds no {what} ({frame.hex(' ')}); "
            f"it holds {len(held)} distinct: {shown or 'none'}"
        )

    def _name_of(self, frame: bytes) -> str:
        return self._describe(frame) if self._describe is not None else frame.hex(" ")


class _ReplayPeer:
    """The far end of the loopback line: answers from the script, on time."""

    def __init__(self, script: ReplayScript, send: Callable[[bytes], None]) -> None:
        self._script = script
        self._send = send
        self._loop = asyncio.get_running_loop()
        self._timers: set[asyncio.TimerHandle] = set()

    def data_received(self, data: bytes) -> None:
        for delay, answer in self._script.answer(bytes(data)):
            self._schedule(delay, answer)

    def _schedule(self, delay: float, data: bytes) -> None:
        def fire() -> None:
            self._timers.discard(timer)
            self._send(data)

        timer = self._loop.call_later(max(delay, 0.0), fire)
        self._timers.add(timer)

    def close(self) -> None:
        for timer in self._timers:
            timer.cancel()
        self._timers.clear()


def replay_connector(script: ReplayScript) -> Callable[[Callable[[], asyncio.Protocol]], Any]:
    """Return a connector whose connections answer from *script* (one cursor for all)."""
    return loopback_connector(lambda send: _ReplayPeer(script, send))
