"""Virtual SJ300 drives on a virtual RS-485 line, served in memory, over TCP and on a pty.

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

I/O part (asyncio, on the loop's clock): :class:`SimulatorEndpoint` (in
memory, through a send callable), :func:`serve_tcp`, :func:`open_pty_server`,
:func:`serve_serial_device` (an existing pty or a real serial port); any of
them paced at a baud rate with :class:`LinePacing` (serve a paced line on
:func:`precise_event_loop`, whose timers keep sub-millisecond time).
"""

from __future__ import annotations

from ._bus import BusModel, SimulatedBus, SimulatorStats, Transmission
from ._device import SerialDeviceServer, serve_serial_device
from ._drive import DEFAULT_EEPROM_WRITE_S, DEFAULT_PROCESSING_S, SimulatedDrive
from ._endpoint import SimulatorEndpoint
from ._faults import Faults
from ._motion import RunState
from ._pacing import LinePacing, PacedLine
from ._parameters_table import Country
from ._precise_loop import precise_event_loop
from ._pty import PtyServer, open_pty_server
from ._tcp import SimulatorServer, serve_tcp
from ._trips import TripCode

__all__ = [
    "DEFAULT_EEPROM_WRITE_S",
    "DEFAULT_PROCESSING_S",
    "BusModel",
    "Country",
    "Faults",
    "LinePacing",
    "PacedLine",
    "PtyServer",
    "RunState",
    "SerialDeviceServer",
    "SimulatedBus",
    "SimulatedDrive",
    "SimulatorEndpoint",
    "SimulatorServer",
    "SimulatorStats",
    "Transmission",
    "TripCode",
    "open_pty_server",
    "precise_event_loop",
    "serve_serial_device",
    "serve_tcp",
]
