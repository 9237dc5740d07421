"""The simulated RS-485 line: up to 32 drives behind one request parser.

:meth:`SimulatedBus.receive` takes the host's bytes (any chunking) and the
time they arrived, and returns what goes back on the line as
:class:`Transmission` values: the reply bytes and how long after ``now``
they start. Sans-IO: the servers schedule the transmissions, tests read
them directly.

Routing, as on a real line where every drive hears every frame:

- a frame for a node with a drive (not silenced) is executed and answered
  after the drive's C078 wait plus its processing time, plus any fault delay;
- a broadcast (FF) of a command that may be broadcast is executed by every
  drive and answered by none; a broadcast of any other command is ignored
  by all (counted);
- a frame for an absent or silenced node gets no answer (counted);
- a damaged frame is answered by the node it names with the NAK of
  :data:`~sj300_async.NAK_FOR_BAD_REQUEST` (a bad BCC with NAK 02 unless
  ``nak_bad_bcc=False``, the other behaviour seen in the field); if the
  node cannot be read, or it is FF, nobody answers.

The bus does not model collisions: if a host sends before the previous
reply is out, both replies are still delivered.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable

from ...sj300.codec import (
    BROADCAST,
    MAX_NODE,
    MIN_NODE,
    NAK_FOR_BAD_REQUEST,
    NakReply,
    Reply,
    Request,
    RequestParser,
    encode_reply,
)
from ...wire import BadFrame, BadFrameReason, Discarded, LocalProtocolError, ParserStats
from .._faults import Faults
from .._model import LineCounters, Transmission
from .._pacing import LinePacing
from ._drive import DEFAULT_EEPROM_WRITE_S, DEFAULT_PROCESSING_S, SimulatedDrive
from ._parameters_table import Country, line_parameters

__all__ = ["SimulatedBus", "SimulatorStats", "simulate"]

_log = logging.getLogger("sj300_async.simulator")


class SimulatorStats(LineCounters):
    """Counters of everything the simulated SJ300 line saw and did."""

    __slots__ = ("broadcasts", "ignored_broadcasts")

    def __init__(self, parser: ParserStats) -> None:
        super().__init__(parser)
        #: Valid broadcast frames executed by every drive.
        self.broadcasts = 0
        #: Broadcasts of commands that may not be broadcast (nobody executes them).
        self.ignored_broadcasts = 0


class SimulatedBus:
    """Virtual SJ300 drives sharing one RS-485 line (see the module docstring).

    Args:
        nodes: the drives' addresses, each 1..32, no repeats.
        factory_defaults: start the drives with true factory values (A001 =
            A002 = 01: serial run and frequency refused) instead of
            configured for serial control.
        country: B085 of every drive.
        wait_ms: set C078 (stored) on every drive.
        line: the line's settings, written into C071 / C073..C075 so a host
            reads back what it talks at (pacing is the servers' job).
        nak_bad_bcc: answer a bad BCC with NAK 02 (else stay silent).
        processing_s, eeprom_write_s: passed to every drive.

    Raises:
        LocalProtocolError: a node is outside 1..32 or repeated, or *wait_ms*
            is outside 0..1000.
    """

    #: The protocol its drives speak (a bus checks a given simulator against its own).
    protocol = "sj300"

    def __init__(
        self,
        nodes: Iterable[int] = (1,),
        *,
        factory_defaults: bool = False,
        country: Country = Country.EUROPE,
        wait_ms: int | None = None,
        line: LinePacing | None = None,
        nak_bad_bcc: bool = True,
        processing_s: float = DEFAULT_PROCESSING_S,
        eeprom_write_s: float = DEFAULT_EEPROM_WRITE_S,
    ) -> None:
        self.drives: dict[int, SimulatedDrive] = {}
        for node in nodes:
            if node in self.drives:
                raise LocalProtocolError(f"node {node} appears twice")
            self.drives[node] = SimulatedDrive(
                node,
                country=country,
                factory_defaults=factory_defaults,
                processing_s=processing_s,
                eeprom_write_s=eeprom_write_s,
            )
        settings = line_parameters(line) if line is not None else {}
        if wait_ms is not None:
            settings["C078"] = wait_ms
        for drive in self.drives.values():
            for code, raw in settings.items():
                drive.set_parameter(code, raw)
        self.nak_bad_bcc = nak_bad_bcc
        self.faults = Faults()
        self._parser = RequestParser()
        self.stats = SimulatorStats(self._parser.stats)
        # Each node's last reply and its frame: a drive hands back the very same reply
        # object while nothing changes (its reads are cached), and a reply is frozen,
        # so its frame is reused. Keeping the reply keeps the identity check sound.
        self._frames: dict[int, tuple[Reply, bytes]] = {}

    def __repr__(self) -> str:
        return f"SimulatedBus(nodes={sorted(self.drives)})"

    def receive(self, data: bytes, now: float) -> list[Transmission]:
        """Feed the host's bytes that arrived at *now*; return the replies, in order."""
        out: list[Transmission] = []
        for event in self._parser.feed(data):
            if isinstance(event, Request):
                self.stats.requests += 1
                reply = self._execute(event, now)
            elif isinstance(event, BadFrame):
                reply = self._answer_bad_frame(event)
            else:
                assert isinstance(event, Discarded)  # counted and logged by the parser
                continue
            if reply is not None:
                sent = self._transmit(reply, now)
                if sent is not None:
                    out.append(sent)
        return out

    def _present(self, node: int | None) -> SimulatedDrive | None:
        """The drive that answers *node*, if one is on the line."""
        if node is None or not MIN_NODE <= node <= MAX_NODE:
            return None
        if self.faults.is_silent(node):
            return None
        return self.drives.get(node)

    def _execute(self, request: Request, now: float) -> tuple[SimulatedDrive, Reply] | None:
        if request.node == BROADCAST:
            if not request.command.spec.broadcast:
                self.stats.ignored_broadcasts += 1
                _log.debug("broadcast of command %s ignored: %r", request.command.name, request)
                return None
            self.stats.broadcasts += 1
            for node, drive in self.drives.items():
                if not self.faults.is_silent(node):
                    drive.handle(request, now)
            return None
        present = self._present(request.node)
        if present is None:
            self.stats.absent += 1
            _log.debug("no drive at node %02d: %s", request.node, request.frame.hex(" "))
            return None
        reply = present.handle(request, now)
        return None if reply is None else (present, reply)

    def _answer_bad_frame(self, frame: BadFrame) -> tuple[SimulatedDrive, Reply] | None:
        code = NAK_FOR_BAD_REQUEST[frame.reason]
        if frame.reason is BadFrameReason.BAD_BCC and not self.nak_bad_bcc:
            code = None
        drive = self._present(frame.node)
        if code is None or drive is None:
            return None  # the parser has counted and logged the frame
        return drive, NakReply(drive.node, code)

    def _transmit(self, answer: tuple[SimulatedDrive, Reply], now: float) -> Transmission | None:
        drive, reply = answer
        frame = self._frame(drive.node, reply)
        extra_delay_s = 0.0
        if self.faults.pending(drive.node):
            faulted = self.faults.apply(drive.node, frame, now + drive.reply_delay_s)
            if faulted is None:
                self.stats.dropped_replies += 1
                _log.debug("node %02d: reply dropped: %s", drive.node, frame.hex(" "))
                return None
            self.stats.corrupted_replies += faulted.corrupted
            self.stats.delayed_replies += faulted.delayed
            frame, extra_delay_s = faulted.data, faulted.extra_delay_s
        self.stats.replies += 1
        if isinstance(reply, NakReply):
            self.stats.naks[reply.code] = self.stats.naks.get(reply.code, 0) + 1
        return Transmission(drive.reply_delay_s + extra_delay_s, frame)

    def _frame(self, node: int, reply: Reply) -> bytes:
        """The frame of *reply* from *node*: encoded, or reused when it is the last reply again."""
        last = self._frames.get(node)
        if last is not None and last[0] is reply:
            return last[1]
        frame = encode_reply(reply)
        self._frames[node] = (reply, frame)
        return frame


def simulate(
    dialect: object, nodes: tuple[int, ...], *, factory_defaults: bool, wait_ms: int | None
) -> SimulatedBus:
    """The simulated line a ``sim://`` SJ300 bus talks to (the dialect's ``simulator``)."""
    bus = SimulatedBus(nodes=nodes, factory_defaults=factory_defaults)
    if wait_ms is not None:
        for drive in bus.drives.values():
            drive.set_wait_ms(wait_ms)
    return bus
