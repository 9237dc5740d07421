"""Virtual drives on a virtual RS-485 line, served in memory, over TCP and on a pty.

The simulator is the other end of every test, the default target of the
CLI and the load generator of the benchmarks, so it answers like a real
drive on a real line, rough edges included: NAKs where a drive gives them,
silence where a drive is silent, wait times, trips, RAM that a power cycle
forgets.

Sans-IO part (no asyncio, no clock: time is passed in as ``now``)::

    bus = SimulatedBus(nodes=range(1, 9))
    out = bus.receive(host_bytes, now)      # -> [Transmission(delay_s, data), ...]
    bus.drives[1].trip(7, now=now)          # E07 over-voltage
    bus.faults.drop_next(1)                 # lose node 1's next reply

Each protocol's drives live in their own package, side by side:
:mod:`sj300_async.simulator.sj300` (:class:`~.sj300.SimulatedBus`) and
:mod:`sj300_async.simulator.fr700` (:class:`~.fr700.Fr700SimulatedBus`).
This package holds what they share: the line model's interface, fault
hooks, pacing, the motion and electrical models, and the servers.

I/O part (asyncio, on the loop's clock): :class:`SimulatorEndpoint` (in
memory, through a send callable), :func:`serve_tcp`, :func:`open_pty_server`,
:func:`serve_serial_device` (an existing pty or a real serial port); any of
them paced at a baud rate with :class:`LinePacing` (serve a paced line on
:func:`precise_event_loop`, whose timers keep sub-millisecond time).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ._command_line import (
    SimulateCommandLine,
    SimulateOption,
    SimulateSettings,
)
from ._endpoint import SimulatorEndpoint
from ._faults import Faults
from ._model import BusModel, LineCounters, Transmission
from ._motion import RunState
from ._pacing import LinePacing, PacedLine, PlausibleLine
from ._precise_loop import precise_event_loop
from ._tap import TapServer, serve_tap
from ._tcp import SimulatorServer, serve_tcp

if TYPE_CHECKING:
    from ._device import SerialDeviceServer, serve_serial_device
    from ._pty import PtyServer, open_pty_server

__all__ = [
    "BusModel",
    "Faults",
    "LineCounters",
    "LinePacing",
    "PacedLine",
    "PlausibleLine",
    "PtyServer",
    "RunState",
    "SerialDeviceServer",
    "SimulateCommandLine",
    "SimulateOption",
    "SimulateSettings",
    "SimulatorEndpoint",
    "SimulatorServer",
    "TapServer",
    "Transmission",
    "open_pty_server",
    "precise_event_loop",
    "serve_serial_device",
    "serve_tap",
    "serve_tcp",
]

#: The POSIX-only servers (pty, termios): imported on first use, so that the
#: rest of the simulator, and sim:// buses, work where those modules do not exist.
_POSIX_ONLY = {
    "PtyServer": "._pty",
    "open_pty_server": "._pty",
    "SerialDeviceServer": "._device",
    "serve_serial_device": "._device",
}


def __getattr__(name: str) -> Any:
    module = _POSIX_ONLY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(module, __name__), name)
