"""The simulated FR-700 line: up to 32 drives (stations 0..31) behind one request parser.

:meth:`Fr700SimulatedBus.receive` takes the host's bytes (any chunking) and
the time they arrived, and returns what goes back on the line as
:class:`~sj300_async.simulator.Transmission` values, exactly like the SJ300
simulated bus, so every server (in memory, TCP, pty, serial device) serves
either.

Routing, as on a real line where every drive hears every frame:

- a request for a station with a drive (not silenced, not restarting after
  a reset) is executed and answered after the request's waiting time (or
  the drive's Pr.123) plus the drive's processing time, plus any fault delay;
- a frame the drives reject (sum, grammar, characters: see
  :mod:`sj300_async.fr700._request_parser`) is answered with its NAK by the
  station it names;
- the host's ACK after read data is taken and not answered; the host's NAK
  (format F) makes the station send its last data reply again;
- a frame for an absent or silenced station gets no answer (counted).

The line options (waiting-time field, terminator) belong to the bus: every
drive on a real line must be set alike (Pr.123, Pr.124) to talk to the host.
By default they are the drives' factory settings: the waiting-time field
expected and every frame ending with CR.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable

from ...fr700.codec import (
    ETX,
    STX,
    BadRequest,
    Fr700Ack,
    Fr700Data,
    Fr700Instruction,
    Fr700LineOptions,
    Fr700Nak,
    Fr700Reply,
    HostAnswer,
    HostRequest,
    RequestParser,
    encode_ack,
    encode_data_reply,
    encode_nak,
    terminator_bytes,
)
from ...wire import Discarded, LocalProtocolError, ParserStats
from .._faults import Faults
from .._model import LineCounters, Transmission
from ._drive import DEFAULT_PROCESSING_S, Fr700SimulatedDrive

__all__ = ["Fr700SimulatedBus", "Fr700SimulatorStats", "corrupt"]

_log = logging.getLogger("sj300_async.simulator.fr700")


def corrupt(frame: bytes) -> bytes:
    """Damage a reply so the host rejects it, keeping its shape.

    A data reply gets the lowest bit of its last data character flipped, so
    its sum no longer matches. ACK and NAK replies have no sum: the first
    station character gets bit 6 flipped (``0`` becomes ``p``), an
    unreadable station. Neither change makes a control byte.
    """
    if frame[0] == STX:
        at = frame.index(ETX) - 1
        return frame[:at] + bytes((frame[at] ^ 0x01,)) + frame[at + 1 :]
    return frame[:1] + bytes((frame[1] ^ 0x40,)) + frame[2:]


class Fr700SimulatorStats(LineCounters):
    """Counters of everything the simulated FR-700 line saw and did."""

    __slots__ = ("host_acks", "reoutputs", "resets")

    def __init__(self, parser: ParserStats) -> None:
        super().__init__(parser)
        #: The host's ACKs after read data.
        self.host_acks = 0
        #: Replies sent again at the host's request (format F).
        self.reoutputs = 0
        #: Inverter resets executed.
        self.resets = 0


class Fr700SimulatedBus:
    """Virtual FR-700 drives sharing one RS-485 line (see the module docstring).

    Args:
        stations: the drives' station numbers, each 0..31, no repeats.
        wait_field: requests carry the waiting-time character (Pr.123 = 9999).
        terminator: ``""``, ``"\\r"`` or ``"\\r\\n"`` (Pr.124), str or bytes.
        factory_defaults: start the drives in external operation mode (run
            and frequency writes refused with NAK A until switched to network).
        processing_s, reset_s: passed to every drive.

    Raises:
        LocalProtocolError: a station outside 0..31 or repeated, or a bad line option.
    """

    #: The protocol its drives speak (a bus checks a given simulator against its own).
    protocol = "fr700"

    def __init__(
        self,
        stations: Iterable[int] = (0,),
        *,
        wait_field: bool = True,
        terminator: str | bytes = "\r",
        factory_defaults: bool = False,
        processing_s: float = DEFAULT_PROCESSING_S,
        reset_s: float = 0.0,
    ) -> None:
        options = Fr700LineOptions(wait_field=wait_field, terminator=terminator_bytes(terminator))
        self.wait_field = options.wait_field
        self.terminator = options.terminator
        self.drives: dict[int, Fr700SimulatedDrive] = {}
        for station in stations:
            if station in self.drives:
                raise LocalProtocolError(f"station {station} appears twice")
            self.drives[station] = Fr700SimulatedDrive(
                station,
                wait_field=options.wait_field,
                factory_defaults=factory_defaults,
                processing_s=processing_s,
                reset_s=reset_s,
            )
        self.faults = Faults(nodes=range(32), corrupt=corrupt)
        self._parser = RequestParser(wait_field=options.wait_field, terminator=options.terminator)
        self.stats = Fr700SimulatorStats(self._parser.stats)

    def __repr__(self) -> str:
        return f"Fr700SimulatedBus(stations={sorted(self.drives)})"

    def receive(self, data: bytes, now: float) -> list[Transmission]:
        """Feed the host's bytes that arrived at *now*; return the replies, in order."""
        out: list[Transmission] = []
        for event in self._parser.feed(data):
            if isinstance(event, Discarded):
                continue  # counted and logged by the parser
            drive = self._present(event.station, now)
            if drive is None:
                self.stats.absent += isinstance(event, HostRequest)
                continue
            sent = self._respond(drive, event, now)
            if sent is not None:
                out.append(sent)
        return out

    def _present(self, station: int | None, now: float) -> Fr700SimulatedDrive | None:
        """The drive that hears *station* now, if one is on the line."""
        if station is None or self.faults.is_silent(station):
            return None
        drive = self.drives.get(station)
        if drive is None or not drive.hears(now):
            return None
        return drive

    def _respond(
        self,
        drive: Fr700SimulatedDrive,
        event: HostRequest | HostAnswer | BadRequest,
        now: float,
    ) -> Transmission | None:
        if isinstance(event, HostRequest):
            self.stats.requests += 1
            reply = drive.handle(event, now)
            if reply is None:
                self.stats.resets += event.instruction == Fr700Instruction.INVERTER_RESET
                return None
            return self._transmit(drive, reply, drive.reply_delay_s(event), now)
        if isinstance(event, BadRequest):
            drive.last_data_reply = None
            return self._transmit(
                drive, Fr700Nak(drive.station, event.code), drive.processing_s, now
            )
        if not event.reoutput:
            self.stats.host_acks += 1
            drive.last_data_reply = None
            return None
        if drive.last_data_reply is None:
            _log.debug("station %02d: asked to re-send, nothing to re-send", drive.station)
            return None
        self.stats.reoutputs += 1
        return self._transmit(drive, drive.last_data_reply, drive.processing_s, now)

    def _transmit(
        self, drive: Fr700SimulatedDrive, reply: Fr700Reply, delay_s: float, now: float
    ) -> Transmission | None:
        """The reply's transmission, *delay_s* after the request arrived (*now*), before faults."""
        frame = self._encode(reply)
        faulted = self.faults.apply(drive.station, frame, now + delay_s)
        if faulted is None:
            self.stats.dropped_replies += 1
            _log.debug("station %02d: reply dropped: %s", drive.station, frame.hex(" "))
            return None
        self.stats.replies += 1
        if isinstance(reply, Fr700Nak):
            self.stats.naks[reply.code] = self.stats.naks.get(reply.code, 0) + 1
        self.stats.corrupted_replies += faulted.corrupted
        self.stats.delayed_replies += faulted.delayed
        return Transmission(delay_s + faulted.extra_delay_s, faulted.data)

    def _encode(self, reply: Fr700Reply) -> bytes:
        if isinstance(reply, Fr700Data):
            return encode_data_reply(reply.station, reply.data, self.terminator)
        if isinstance(reply, Fr700Ack):
            return encode_ack(reply.station, self.terminator)
        return encode_nak(reply.station, reply.code, self.terminator)


def simulate(
    dialect: object, nodes: tuple[int, ...], *, factory_defaults: bool, wait_ms: int | None
) -> Fr700SimulatedBus:
    """The simulated line a ``sim://`` FR-700 bus talks to (the dialect's ``simulator``).

    Its drives follow the dialect's line options (waiting-time field, terminator).
    """
    # Duck-typed: the dialect module imports the async drive, the simulator stays sans-IO.
    options = getattr(dialect, "options", None)
    if not isinstance(options, Fr700LineOptions):
        raise LocalProtocolError(f"an FR-700 simulator needs an FR-700 dialect, got {dialect!r}")
    bus = Fr700SimulatedBus(
        nodes,
        wait_field=options.wait_field,
        terminator=options.terminator,
        factory_defaults=factory_defaults,
    )
    if wait_ms is not None:
        for drive in bus.drives.values():
            drive.set_wait_ms(wait_ms)
    return bus
