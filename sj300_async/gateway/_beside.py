"""What is read beside the poll: each drive's trip history and set frequency, when due.

A trip history is not part of the poll cycle (an SJ300's is 446
characters: most of a 19200-baud cycle). For a protocol whose profile
reads one, each drive's is read every ``trips_interval_s`` and as soon as
its status shows a trip. The set frequency is read every
``setpoint_interval_s`` and at least twice per ``stale_after_s``, unless it
is polled. A failed read is counted and tried again when due.

The line's settings are read at every turn, not once: a reload that retunes
the line (:mod:`._reload`) changes the next turn's intervals, and what was
learnt so far (trips seen, reads that failed) carries over.
"""

from __future__ import annotations

import asyncio
import functools
import logging
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, TypeVar

from ..profiles import NEVER
from ..wire import SJ300Error
from ._drive import GatewayDrive

if TYPE_CHECKING:
    from ._gateway import GatewayLine

__all__ = ["read_beside_the_poll"]

_log = logging.getLogger("sj300_async.gateway")
_T = TypeVar("_T")


async def read_beside_the_poll(
    line: GatewayLine,
    stale_after_s: Callable[[], float],
    changed: Callable[[GatewayDrive], None],
    errors: dict[tuple[str, str], int],
) -> None:
    """Read *line*'s trip histories and set frequencies when due, until cancelled.

    *changed* is told of a drive whose readings a read changed; a failed read
    counts in *errors* under ``(line, "trips" | "setpoint")``.
    """
    loop = asyncio.get_running_loop()
    seen_trip: dict[int, bool] = {}
    # When each read last failed: a failure waits its interval too (no read per cycle).
    failed_at: dict[tuple[str, int], float] = {}

    def due(what: str, node: int, last_read: float, interval_s: float) -> bool:
        last = max(last_read, failed_at.get((what, node), NEVER))
        return loop.time() - last >= interval_s

    while True:
        config, profile = line.config, line.profile
        await asyncio.sleep(max(config.interval_s, 0.05))
        config = line.config  # a reload may have retuned it meanwhile
        trips = profile.capabilities.trip_history and config.trips_interval_s > 0
        setpoint_polled = profile.setpoint_parameter in config.parameters
        setpoints = config.setpoint_interval_s > 0 and not setpoint_polled
        # Twice per stale_after_s at least: read once per stale_after_s, the value
        # aged past it before each read (a 9600-baud line of 8 drives: 11 of 294
        # samples of register 1003 answered 0x0B with 5 s and 5 s).
        setpoint_every = min(config.setpoint_interval_s, stale_after_s() / 2)
        for drive in line.drives.values():
            readings = drive.readings
            if not readings.online:
                continue
            target = line.bus.drive(drive.node)
            tripped = bool(readings.status_view is not None and readings.status_view.tripped)
            new_trip = tripped and not seen_trip.get(drive.node, False)
            if trips and (
                new_trip or due("trips", drive.node, readings.trips_at, config.trips_interval_s)
            ):
                history = await _read(
                    line, drive, "trips", functools.partial(profile.read_trips, target), errors
                )
                seen_trip[drive.node] = tripped  # a failed read is tried when due
                if history is None:
                    failed_at["trips", drive.node] = loop.time()
                else:
                    readings.set_trips(history, loop.time(), profile)
                    changed(drive)
            if setpoints and due("setpoint", drive.node, readings.set_frequency_at, setpoint_every):
                hz = await _read(
                    line,
                    drive,
                    "setpoint",
                    functools.partial(profile.read_set_frequency, target),
                    errors,
                )
                if hz is None:
                    failed_at["setpoint", drive.node] = loop.time()
                else:
                    readings.set_frequency(hz, loop.time())
                    changed(drive)


async def _read(
    line: GatewayLine,
    drive: GatewayDrive,
    what: str,
    read: Callable[[], Awaitable[_T]],
    errors: dict[tuple[str, str], int],
) -> _T | None:
    """One read beside the poll, after any pending stop; None (counted) if it failed."""
    try:
        await line.controller.gate.wait_open()  # a pending stop has the line first
        return await read()
    except SJ300Error as exc:
        key = (line.config.name, what)
        errors[key] = errors.get(key, 0) + 1
        _log.debug("line %s node %d: %s read failed: %s", line.config.name, drive.node,
                   what, exc)  # fmt: skip
        return None
