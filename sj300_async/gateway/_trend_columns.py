"""What the gateway's trend of a drive keeps of each sample: every polled field, by name.

The core keeps one :class:`~._trend.Trend` per drive (:class:`~._drive.GatewayDrive`'s
``trend``): the workbench's graph reads its frequency, current and voltage,
and a trip record (:mod:`.recorder`) all of it around the trip. Its columns
are those of a line: the monitor's values, the set frequency, the status's
running and tripped flags, the direction, then each parameter the line
polls (by its code).

Decisions:

- **A sample is a monitor read.** A snapshot made by a write's read-back or a
  trip history read repeats the monitor it had, and is not a sample (the
  trend keeps one per poll of the monitor: the poll's rate). The other
  columns are their latest value at that read.
- **Numbers only.** A flag is 1 or 0, the direction 1 (forward), -1
  (reverse) or 0 (stopped), each as the trend keeps numbers (thousandths);
  :func:`served_columns` turns them back into JSON's ``true``, ``false``,
  ``"forward"``. A value not read yet is null.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Final

from ..profiles import DriveSnapshot
from ..wire import Direction
from ._trend import VALUES

__all__ = ["FLAGS", "MONITOR", "columns_of", "sample_of", "served_columns"]

#: The columns every drive's trend has, in this order (the workbench's three first).
MONITOR: Final = (
    *VALUES,
    "output_torque_percent",
    "power_kw",
    "set_frequency_hz",
    "running",
    "tripped",
    "direction",
)
#: The columns that hold a flag (1 or 0).
FLAGS: Final = frozenset({"running", "tripped"})
_DIRECTIONS: Final = {Direction.FORWARD: 1.0, Direction.REVERSE: -1.0, Direction.STOP: 0.0}
_DIRECTION_NAMES: Final = {1.0: "forward", -1.0: "reverse", 0.0: "stop"}


def columns_of(parameters: Sequence[str]) -> tuple[str, ...]:
    """The names of a drive's trend columns on a line that polls *parameters*."""
    return (*MONITOR, *parameters)


def _flag(value: bool | None) -> float | None:
    return None if value is None else float(value)


def sample_of(parameters: Sequence[str]) -> Callable[[DriveSnapshot], tuple[float | None, ...]]:
    """What a snapshot gives each column, for a line that polls *parameters*."""
    codes = tuple(parameters)

    def sample(snapshot: DriveSnapshot) -> tuple[float | None, ...]:
        readings = snapshot.parameters
        direction = snapshot.direction
        return (
            snapshot.output_frequency_hz,
            snapshot.output_current_a,
            snapshot.output_voltage_v,
            snapshot.output_torque_percent,
            snapshot.power_kw,
            snapshot.set_frequency_hz,
            _flag(snapshot.running),
            _flag(snapshot.tripped),
            None if direction is None else _DIRECTIONS.get(direction),
            *(r.value if (r := readings.get(code)) is not None else None for code in codes),
        )

    return sample


def served_columns(
    columns: dict[str, list[float | None]],
) -> dict[str, list[float | bool | str | None]]:
    """*columns* (a trend's) as JSON serves them: flags as booleans, the direction named."""
    out: dict[str, list[float | bool | str | None]] = {}
    for name, values in columns.items():
        if name in FLAGS:
            out[name] = [None if v is None else v != 0 for v in values]
        elif name == "direction":
            out[name] = [None if v is None else _DIRECTION_NAMES.get(v) for v in values]
        else:
            out[name] = list(values)
    return out
