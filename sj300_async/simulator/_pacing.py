"""Wire time: how long characters take on a serial line, and a line that makes bytes wait for it.

:class:`LinePacing` is the arithmetic: one character is a start bit, the
data bits, the parity bit if any and the stop bits, at the baud rate.
:class:`PacedLine` books the one half-duplex wire the host and the drives
share, so a server can hand bytes over no earlier than a real line would
have delivered them. Both are sans-IO: they compute times, the servers
schedule.
"""

from __future__ import annotations

import math
from typing import Final

from ..wire import LineSettings, LocalProtocolError

__all__ = ["PLAUSIBLE_PACING", "LinePacing", "PacedLine", "PlausibleLine", "server_line"]

#: A paced reply is handed over in groups of characters about this long, so a
#: 446-byte trip history does not need 446 timers; no byte is ever early, but
#: each one of a group but the last is late by up to a group's time, and a
#: host reads once per group. A line that stands in for a UART whose timing is
#: measured (the wire benchmark's) uses ``group_s=0``: each character is handed
#: over when its stop bit ends, and characters that fall due together (a late
#: wake-up) go out in one write (``SimulatorEndpoint``).
DEFAULT_GROUP_S: Final = 0.004
#: The shortest reply a host's plausibility floor may count on, in characters:
#: an SJ300 NAK (9), longer than any other shortest reply (an SJ300 ACK is 7,
#: an FR-700 NAK with CR LF 6, its ACK 4 or 5).
MIN_REPLY_CHARS: Final = 9


#: The line settings that pace a simulated line: the library's own LineSettings
#: (one definition of character time for the host's time-outs and the
#: simulator's pacing). An instant line (baud rate 0) cannot be paced.
LinePacing = LineSettings

#: The fastest line the simulated drives run (both protocols top out at 19200
#: baud): the servers' default pacing, so that no reply reaches a host sooner
#: than a real line could carry the request and the reply (the host's
#: plausibility floor, ``BusTiming.answer_floor``, rejects faster ones).
PLAUSIBLE_PACING: Final = LineSettings(19200)


class PacedLine:
    """The shared wire: one character at a time, in either direction.

    Host bytes and replies queue behind whatever the line carries already
    (half duplex), so two servers or two TCP clients on one bus share one
    line's capacity when they share a :class:`PacedLine`.
    """

    def __init__(self, pacing: LinePacing, *, group_s: float = DEFAULT_GROUP_S) -> None:
        if pacing.baudrate <= 0:
            raise LocalProtocolError("an instant line (baud rate 0) cannot be paced")
        self.pacing = pacing
        #: How many characters a delivery group holds (at least one).
        self.group_chars = max(1, int(group_s / pacing.char_time_s))
        self._free_at = -math.inf

    @property
    def free_at(self) -> float:
        """When the last booked character has crossed the line."""
        return self._free_at

    def receive(self, now: float, data: bytes) -> list[tuple[float, bytes]]:
        """Book host bytes written at *now*; return ``(arrival time, bytes)`` pieces.

        A piece ends after each CR, so a drive sees every frame complete at the
        moment its CR has crossed the line, not when a later frame in the same
        write has.
        """
        pieces: list[tuple[float, bytes]] = []
        char_s = self.pacing.char_time_s
        start = max(now, self._free_at)
        sent = 0
        while sent < len(data):
            cr = data.find(b"\r", sent)
            end = len(data) if cr < 0 else cr + 1
            pieces.append((start + end * char_s, data[sent:end]))
            sent = end
        self._free_at = start + len(data) * char_s
        return pieces

    def transmit(self, start: float, data: bytes) -> list[tuple[float, bytes]]:
        """Book reply bytes that may start at *start*; return ``(delivery time, bytes)`` groups.

        Each group is delivered when its last character has crossed the line.
        """
        char_s = self.pacing.char_time_s
        begin = max(start, self._free_at)
        step = self.group_chars
        groups = [
            (begin + min(i + step, len(data)) * char_s, data[i : i + step])
            for i in range(0, len(data), step)
        ]
        self._free_at = begin + len(data) * char_s
        return groups


class PlausibleLine(PacedLine):
    """Not quite a paced line: only as slow as physics must be.

    The drives hear the host's bytes at once and answer after their own
    delays, as on an unpaced line, but no reply reaches the host sooner than
    the request and a :data:`MIN_REPLY_CHARS`-character frame could have
    crossed the line: the quickest any real drive answers. A host's
    plausibility floor (``BusTiming.answer_floor``) refuses anything faster
    as a duplicate or a stray. Each reply goes over whole, in one delivery;
    for true wire timing, pace the line (:class:`PacedLine`).
    """

    def __init__(self, pacing: LinePacing = PLAUSIBLE_PACING) -> None:
        super().__init__(pacing)
        self._request_end = -math.inf

    def receive(self, now: float, data: bytes) -> list[tuple[float, bytes]]:
        """Book the host's bytes as if they crossed the line; hand them over at once."""
        self._request_end = max(now, self._request_end) + len(data) * self.pacing.char_time_s
        return [(now, data)]

    def transmit(self, start: float, data: bytes) -> list[tuple[float, bytes]]:
        """The whole reply, at *start* or once the shortest exchange could have ended."""
        earliest = self._request_end + MIN_REPLY_CHARS * self.pacing.char_time_s
        return [(max(start, earliest), data)]


def server_line(pacing: LinePacing | None, line: PacedLine | None) -> PacedLine | None:
    """The line a server (TCP, pty, serial device) paces on.

    *line* if given; else *pacing*'s own (an instant line, baud rate 0: none,
    replies go out as soon as the drive has answered); else a
    :class:`PlausibleLine` at :data:`PLAUSIBLE_PACING`. A host on the other
    end of a socket or a pty cannot tell a simulator from a drive, and a
    reply faster than any line is one it rightly refuses; a host that knows
    better opens its bus with an instant line (``LineSettings(baudrate=0)``)
    and may then serve with ``pacing=LineSettings(baudrate=0)``.
    """
    if line is not None:
        return line
    if pacing is None:
        return PlausibleLine()
    return PacedLine(pacing) if pacing.baudrate else None
