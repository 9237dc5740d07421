"""The six-deep trip history a drive keeps in non-volatile memory, and what a trip records.

The trip codes themselves (:class:`~sj300_async.sj300.TripCode`, with their
meanings) belong to the codec; this module uses them.

The history survives a power cycle (a real drive writes it at the moment of
the trip); only command 08 with B084 = 00 or 02 clears it. The total count
keeps counting past six.
"""

from __future__ import annotations

from typing import Final

from ...sj300.codec import StatusA, TripCode, TripHistory, TripRecord, TripStatusB, TripStatusC
from .._motion import RunState

__all__ = ["EMPTY_RECORD", "TripLog", "overcurrent_code", "trip_status_b"]

_DEPTH: Final = 6
_MAX_COUNT: Final = 99_999_999  # what the 8-digit total field can carry


#: The trip-record Status B bit each hardware trip sets (the manual's bit table).
_STATUS_B_BITS: Final[dict[int, TripStatusB]] = {
    TripCode.GROUND_FAULT: TripStatusB.GROUND_FAULT,
    TripCode.UNDER_VOLTAGE: TripStatusB.UNDER_VOLTAGE,
    TripCode.OVER_VOLTAGE: TripStatusB.OVER_VOLTAGE,
    TripCode.THERMAL: TripStatusB.THERMAL,
    TripCode.GATE_ARRAY: TripStatusB.GATE_ARRAY,
    # E30 can be any of three phases; the simulator always blames U.
    TripCode.IGBT: TripStatusB.IGBT_U,
}

_OVERCURRENT: Final = {
    RunState.CONSTANT_SPEED: TripCode.OVER_CURRENT_CONSTANT,
    RunState.DECELERATING: TripCode.OVER_CURRENT_DECEL,
    RunState.ACCELERATING: TripCode.OVER_CURRENT_ACCEL,
}

#: An unused history slot: every field zero.
EMPTY_RECORD: Final = TripRecord(
    trip_factor=0,
    status_a=StatusA(0),
    status_b=TripStatusB(0),
    status_c=TripStatusC(0),
    output_frequency_hz=0.0,
    run_time_h=0,
    output_current_a=0.0,
    output_voltage_v=0.0,
    power_on_time_h=0,
)


def trip_status_b(code: int) -> TripStatusB:
    """The trip-record Status B bits of a trip factor (0 for causes without a bit)."""
    return _STATUS_B_BITS.get(code, TripStatusB(0))


def overcurrent_code(state: RunState) -> TripCode:
    """The over-current trip (E01..E04) a drive in *state* reports."""
    return _OVERCURRENT.get(state, TripCode.OVER_CURRENT_OTHER)


class TripLog:
    """The total trip count and the six most recent records, newest first."""

    __slots__ = ("_history", "_records", "total")

    def __init__(self) -> None:
        #: Trips since the history was last cleared (the count keeps going past six).
        self.total = 0
        self._records: list[TripRecord] = []
        # What history() returned, until the next record or clear: a TripHistory is
        # immutable, and a drive that answers it again can reuse its encoding.
        self._history: TripHistory | None = None

    def record(self, record: TripRecord) -> None:
        """Add a trip as the most recent; the seventh oldest falls out."""
        self._records.insert(0, record)
        del self._records[_DEPTH:]
        self.total = min(self.total + 1, _MAX_COUNT)
        self._history = None

    def clear(self) -> None:
        """Forget every trip (command 08 with B084 = 00 or 02)."""
        self._records.clear()
        self.total = 0
        self._history = None

    def history(self) -> TripHistory:
        """The command 05 payload: count and six slots, empty ones zero.

        The same object until the log changes.
        """
        if self._history is None:
            padding = [EMPTY_RECORD] * (_DEPTH - len(self._records))
            self._history = TripHistory(self.total, (*self._records, *padding))
        return self._history
