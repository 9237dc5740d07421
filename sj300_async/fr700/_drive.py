"""The typed FR-700 Drive API: one method per thing a user does with a drive.

Get one from an FR-700 bus: ``open_bus(url, protocol="fr700")`` then
``bus.drive(station)`` (stations 0..31). Every method validates its
arguments before anything reaches the wire and raises the library's typed
errors: :class:`~sj300_async.LocalProtocolError` (nothing sent),
:class:`~sj300_async.NakError` (``.code`` an :class:`Fr700NakCode`),
:class:`~sj300_async.ReplyTimeoutError`,
:class:`~sj300_async.RemoteProtocolError`,
:class:`~sj300_async.TransportError`, :class:`~sj300_async.ReadOnlyError`.

Parameters: :meth:`Fr700Drive.read_parameter` / :meth:`~Fr700Drive.write_parameter`
take and return the value in the parameter's unit (Pr.7 = 5.0 s), scaled
by the catalogue (:mod:`._parameters`, which refuses numbers it does not
list); :meth:`~Fr700Drive.read_parameter_raw` /
:meth:`~Fr700Drive.write_parameter_raw` the raw integer 0..65535 of any
parameter. Either way they go through the link-parameter extension: the bank is written
with HFF, then the parameter is read or written at its offset. The two
transactions hold a per-drive lock, so another task cannot switch the bank
in between. A write always writes its bank first: a restarted drive is back
in bank 0, and a write that trusted a remembered bank would change
Pr.N - 100 (a review's script set Pr.8 to 60 s writing "Pr.108"), so the
extra request is the price of never writing the wrong parameter. A read
reuses the bank last written while nothing says the drive may have
restarted: a refusal (NAK) keeps it (the drive answered, and only a bank
write changes its bank), so walking every number of a bank (most of which
a drive lacks: NAK B) writes the bank once. It is forgotten after any
other error in such a pair, after an inverter reset, after a raw HFF write
(:meth:`Fr700Drive.write`), and whenever this drive's time-outs, retries
or transport errors or the link's connections have moved since it was
written (:meth:`Fr700Drive._bank_epoch`), and when the drive last answered
a parameter or bank request more than :data:`BANK_TRUST_S` ago: a drive
that restarts answers nothing for far longer than that (a power cycle, an
inverter reset: a decision, the reference gives no figure), so a walk of
reads, one every few milliseconds, writes its bank once, while a read
after a pause, in which a restart may have gone unseen, writes it again.
The retries of a parameter request are made here, each after a bank write
(:meth:`Fr700Drive._in_bank`): the bus's own retry of an attempt a restart
met would land in bank 0.
Selecting a bank only prepares a read, so a read-only bus allows it.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Coroutine
from typing import TYPE_CHECKING, Any

from ..bus import TransactionStats
from ..wire import (
    Direction,
    LocalProtocolError,
    NakError,
    RemoteProtocolError,
    ReplyTimeoutError,
)
from . import _requests as rq
from ._codec import DEFAULT_LINE_OPTIONS, Fr700LineOptions
from ._codes import Fr700Instruction, Fr700OperationMode, Fr700StatusBits
from ._faults import Fr700FaultHistory, decode_fault_history
from ._parameters import fr700_parameter_info
from ._payloads import Fr700Monitor, Fr700MultiReply, Fr700Status, decode_hex, decode_multi_reply
from ._requests import Fr700MultiReceive, Fr700Request

#: Seconds after the drive's last answer to a parameter or bank request during which
#: a read trusts the bank written last (module docstring).
BANK_TRUST_S = 0.2

if TYPE_CHECKING:
    from ..bus import Channel

__all__ = ["Fr700Drive"]

I = Fr700Instruction  # noqa: E741


class Fr700Drive:
    """One FR-700 drive on a bus. Get it from :meth:`Bus.drive` on an FR-700 bus.

    Attributes:
        station: the drive's station number (0..31, its Pr.117).
        stats: counters of this drive's transactions.
        wait_time_s: the drive's fixed waiting time (Pr.123) when requests
            carry no waiting-time field; the response time-out grows by it.
        timeout_s: a fixed response time-out for this drive (None: computed).
    """

    def __init__(
        self,
        channel: Channel[Fr700Request],
        station: int,
        *,
        options: Fr700LineOptions = DEFAULT_LINE_OPTIONS,
        wait_time_s: float = 0.0,
    ) -> None:
        if isinstance(station, bool) or not isinstance(station, int) or not 0 <= station <= 31:
            raise LocalProtocolError(f"an FR-700 station is 0..31, got {station!r}")
        self._channel = channel
        self._station = station
        self._options = options
        self.stats = TransactionStats()
        self.wait_time_s = wait_time_s
        self.timeout_s: float | None = None
        self._bank: int | None = None
        self._bank_written_at: tuple[int, int] = (-1, -1)  # _bank_epoch() then
        self._bank_answered_at = -math.inf  # loop time of the last answer in a bank
        self._bank_lock = asyncio.Lock()

    @property
    def station(self) -> int:
        """The station number."""
        return self._station

    @property
    def node(self) -> int:
        """The station number (the name every drive on a bus shares)."""
        return self._station

    def __repr__(self) -> str:
        return f"<Fr700Drive {self._station:02d} on {self._channel.description}>"

    # -- transactions ----------------------------------------------------------------

    async def _execute(self, request: Fr700Request, *, urgent: bool = False) -> None:
        if request.expects_reply:
            await self._data(request, urgent=urgent)
        else:  # the inverter reset: nothing answers
            await self._channel.send(request, self.stats, urgent=urgent)

    def _data(self, request: Fr700Request, *, urgent: bool = False) -> Coroutine[Any, Any, bytes]:
        # Not a coroutine itself: the caller awaits the arbiter's, one frame less on
        # every resume of a transaction (see Channel.transact).
        return self._channel.transact(
            request, self.stats, wait_s=self.wait_time_s, timeout_s=self.timeout_s, urgent=urgent
        )

    async def _value(self, instruction: int) -> int:
        return decode_hex(
            await self._data(rq.read(self._station, instruction, options=self._options))
        )

    async def _write(self, instruction: int, value: int, *, urgent: bool = False) -> None:
        request = rq.write(self._station, instruction, value, options=self._options)
        await self._execute(request, urgent=urgent)

    # -- raw access --------------------------------------------------------------------

    async def read_data(self, code: int | str, *, width: int | None = None) -> bytes:
        """Read any instruction H00..H7F; return the reply's data characters as sent.

        Args:
            width: data characters the reply must have (default: the
                instruction's known width, else any).

        Raises:
            LocalProtocolError: not a read code (nothing sent).
            NakError: e.g. B when the drive has no such instruction.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
        """
        request = rq.read(self._station, code, options=self._options, reply_width=width)
        return await self._data(request)

    async def read(self, code: int | str, *, width: int | None = None) -> int:
        """Read any instruction H00..H7F; return its hex data as an int.

        Raises as :meth:`read_data`, and RemoteProtocolError when the data is not hex.
        """
        return decode_hex(await self.read_data(code, width=width))

    async def write(self, code: int | str, value: int, *, digits: int | None = None) -> None:
        """Write *value* to any instruction H80..HFF (HF0: :meth:`multi_command`).

        Args:
            digits: 2 or 4 hex digits (default: the instruction's known width, else 4).

        Raises:
            LocalProtocolError: not a write code, or a value that does not fit (nothing sent).
            NakError: A (mode), B (no such instruction), C (data range) and
                transmission errors.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        request = rq.write(self._station, code, value, options=self._options, digits=digits)
        await self._execute(request)
        if request.instruction in (I.INVERTER_RESET, I.WRITE_LINK_EXTENSION):
            self._bank = None  # a restart's bank 0, or one chosen behind our back

    # -- status and monitors -------------------------------------------------------------

    async def read_status(self) -> Fr700Status:
        """H7A: the status monitor (RUN, forward, reverse, SU, OL, IPF, FU, ABC1).

        Raises:
            NakError: the drive refused the request.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
        """
        return Fr700Status(Fr700StatusBits(await self._value(I.STATUS)))

    async def read_extended_status(self) -> Fr700Status:
        """H79: the extended status monitor (16 bits). Raises as :meth:`read_status`."""
        return Fr700Status(Fr700StatusBits(await self._value(I.EXTENDED_STATUS)), extended=True)

    async def read_output_frequency(self) -> float:
        """H6F: the output frequency in Hz. Raises as :meth:`read_status`."""
        return await self._value(I.OUTPUT_FREQUENCY) / 100

    async def read_output_current(self) -> float:
        """H70: the output current in A. Raises as :meth:`read_status`."""
        return await self._value(I.OUTPUT_CURRENT) / 100

    async def read_output_voltage(self) -> float:
        """H71: the output voltage in V. Raises as :meth:`read_status`."""
        return await self._value(I.OUTPUT_VOLTAGE) / 10

    async def read_monitor(self) -> Fr700Monitor:
        """H6F, H70 and H71 (three transactions). Raises as :meth:`read_status`."""
        return Fr700Monitor(
            output_frequency_hz=await self.read_output_frequency(),
            output_current_a=await self.read_output_current(),
            output_voltage_v=await self.read_output_voltage(),
        )

    # -- run and frequency -----------------------------------------------------------------

    async def run_forward(self) -> None:
        """HFA H02: run forward.

        Raises:
            NakError: A when the drive is not in network operation mode.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        await self._execute(rq.run(self._station, Direction.FORWARD, options=self._options))

    async def run_reverse(self) -> None:
        """HFA H04: run reverse. Raises as :meth:`run_forward`."""
        await self._execute(rq.run(self._station, Direction.REVERSE, options=self._options))

    async def stop(self) -> None:
        """HFA H00: stop. Jumps the queue: it goes out before every waiting poll.

        Raises as :meth:`run_forward`.
        """
        request = rq.run(self._station, Direction.STOP, options=self._options)
        await self._execute(request, urgent=True)

    async def set_frequency(self, hz: float, *, eeprom: bool = False) -> None:
        """HED (RAM) or, with *eeprom*, HEE (RAM and EEPROM): the set frequency in Hz.

        Raises:
            LocalProtocolError: not a number in 0..655.35 or finer than 0.01 Hz (nothing sent).
            NakError: C above the drive's maximum frequency, A outside network mode.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        await self._execute(
            rq.set_frequency(self._station, hz, eeprom=eeprom, options=self._options)
        )

    async def read_fault_history(self) -> Fr700FaultHistory:
        """H74..H77: the last eight trips, most recent first, each named (four reads).

        Raises as :meth:`read_status`.
        """
        words = [await self._value(I.FAULT_HISTORY + i) for i in range(4)]
        return decode_fault_history(words)

    async def read_set_frequency(self, *, eeprom: bool = False) -> float:
        """H6D (RAM) or, with *eeprom*, H6E (EEPROM): the set frequency in Hz.

        Raises as :meth:`read_status`.
        """
        code = I.READ_SET_FREQUENCY_EEPROM if eeprom else I.READ_SET_FREQUENCY_RAM
        return await self._value(code) / 100

    async def multi_command(
        self,
        direction: Direction | int,
        hz: float,
        *,
        eeprom: bool = False,
        receive: Fr700MultiReceive | int = Fr700MultiReceive.OUTPUT_FREQUENCY,
    ) -> Fr700MultiReply:
        """HF0: run command and set frequency in one request; status and a monitor back.

        The reply says how each half fared (:attr:`Fr700MultiReply.run_error`,
        :attr:`~Fr700MultiReply.frequency_error`): a mode or range error of one
        half is reported there, not raised, so the monitor value is not lost.

        Raises:
            LocalProtocolError: a bad direction, frequency or receive type (nothing sent).
            NakError: errors other than mode and range (e.g. transmission errors).
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        request = rq.multi_command(
            self._station,
            rq.run_bits(direction),
            hz,
            eeprom=eeprom,
            receive=receive,
            options=self._options,
        )
        return decode_multi_reply(await self._data(request))

    # -- operation mode and reset --------------------------------------------------------------

    async def read_operation_mode(self) -> Fr700OperationMode:
        """H7B: network, external or PU operation. Raises as :meth:`read_status`."""
        return Fr700OperationMode(await self._value(I.READ_OPERATION_MODE))

    async def set_operation_mode(self, mode: Fr700OperationMode | int) -> None:
        """HFB: switch the operation mode.

        Raises:
            LocalProtocolError: not NETWORK, EXTERNAL or PU (nothing sent).
            NakError: A while running, C for a mode the drive refuses.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        await self._execute(rq.write_operation_mode(self._station, mode, options=self._options))

    async def reset(self) -> None:
        """HFD H9696: reset the inverter (clears a fault). The drive sends no reply.

        A real drive takes about a second to restart and answers nothing
        meanwhile: the next request may time out and be retried.

        Raises:
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        self._bank = None
        await self._execute(rq.reset(self._station, options=self._options))

    # -- parameters ----------------------------------------------------------------------------

    async def read_parameter(self, number: int | str) -> float:
        """Read parameter *number* (``7`` or ``"Pr.7"``) in its unit, scaled by the catalogue.

        Pr.7 (acceleration time, 0.1 s increments) reading raw 50 returns
        5.0; a special setting returns itself (Pr.122 "9999" is 9999.0). See
        :data:`~sj300_async.fr700.FR700_PARAMETERS`.

        Raises:
            LocalProtocolError: not a parameter number, or one the catalogue
                does not list (use :meth:`read_parameter_raw`); nothing sent.
            NakError: e.g. B for a parameter the drive does not have.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
        """
        info = fr700_parameter_info(number)
        return info.from_raw(await self.read_parameter_raw(info.number))

    async def write_parameter(self, number: int | str, value: float) -> None:
        """Write *value*, in the parameter's unit, to parameter *number* (``7`` or ``"Pr.7"``).

        ``write_parameter(7, 2.5)`` sets a 2.5 s acceleration time (raw 25).
        Special settings are written as such (``write_parameter(122, 9999)``).

        Raises:
            LocalProtocolError: not a parameter number, one the catalogue does
                not list (use :meth:`write_parameter_raw`), or a value out of
                range or finer than the increment (nothing sent).
            NakError: A (not writable in this mode or while running), B (no such
                parameter), C (out of range).
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        info = fr700_parameter_info(number)
        await self.write_parameter_raw(info.number, info.to_raw(value))

    async def read_parameter_raw(self, number: int | str) -> int:
        """Read parameter *number* (0..999, or ``"Pr.7"``): its raw value 0..65535.

        The value counts the parameter's setting increment (Pr.7 in 0.1 s);
        any number is accepted, the drive judges. :meth:`read_parameter`
        scales it.

        Raises:
            LocalProtocolError: not a parameter number (nothing sent).
            NakError: e.g. B for a parameter the drive does not have.
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
        """
        bank, _offset = rq.parameter_bank(number)
        request = rq.read_parameter(self._station, number, options=self._options)
        return decode_hex(await self._in_bank(bank, request, write=False))

    async def write_parameter_raw(self, number: int | str, value: int) -> None:
        """Write the raw *value* (0..65535) to parameter *number* (0..999, or ``"Pr.7"``).

        Raises:
            LocalProtocolError: bad number or value (nothing sent).
            NakError: A (not writable in this mode or while running), B (no such
                parameter), C (out of range).
            ReplyTimeoutError: no valid answer in time (after the bus's retries).
            RemoteProtocolError: the answer broke the protocol (after the bus's retries).
            TransportError: the link is down, or a write failed.
            ReadOnlyError: the bus is read-only and the request changes a drive (nothing sent).
        """
        request = rq.write_parameter(self._station, number, value, options=self._options)
        self._channel.check(request)  # refuse before switching the bank, not after it
        bank, _offset = rq.parameter_bank(number)
        await self._in_bank(bank, request, write=True)

    async def _in_bank(self, bank: int, request: Fr700Request, *, write: bool) -> bytes:
        """*request* (a parameter read or write) in *bank*, under the bank lock.

        The retries are made here, not by the bus: each attempt follows a bank
        write the drive acknowledged (a write's first too, a read's when the
        bank may not hold), so an attempt that a restart met cannot be tried
        again in bank 0 (module docstring).
        """
        tries = self._channel.retries_allowed() + 1
        async with self._bank_lock:
            for attempt in range(tries):
                await self._select_bank(bank, always=write or attempt > 0)
                try:
                    data = await self._channel.transact(
                        request,
                        self.stats,
                        wait_s=self.wait_time_s,
                        timeout_s=self.timeout_s,
                        retries=0,
                    )
                    self._bank_answered_at = asyncio.get_running_loop().time()
                    return data
                except NakError:
                    self._bank_answered_at = asyncio.get_running_loop().time()
                    raise  # the drive answered: its bank holds
                except (ReplyTimeoutError, RemoteProtocolError):
                    self._bank = None
                    if attempt + 1 == tries:
                        raise
                    self.stats.retries += 1
                except BaseException:
                    self._bank = None
                    raise
        raise AssertionError("unreachable: the last attempt returns or raises")

    def _bank_epoch(self) -> tuple[int, int]:
        """What must not move for the bank last written to hold (module docstring)."""
        stats = self.stats
        return stats.timeouts + stats.retries + stats.transport_errors, self._channel.connects

    async def _select_bank(self, bank: int, *, always: bool = False) -> None:
        if (
            not always
            and self._bank == bank
            and self._bank_written_at == self._bank_epoch()
            and asyncio.get_running_loop().time() - self._bank_answered_at <= BANK_TRUST_S
        ):
            return
        self._bank = None  # unknown until the drive has acknowledged
        request = rq.link_extension(self._station, bank, options=self._options, changes_drive=False)
        await self._execute(request)
        self._bank = bank
        self._bank_written_at = self._bank_epoch()
        self._bank_answered_at = asyncio.get_running_loop().time()
