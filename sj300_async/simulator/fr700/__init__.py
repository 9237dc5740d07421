"""Virtual Mitsubishi FR-700 drives on a virtual RS-485 line (the computer link).

The same machinery as the SJ300 simulator: :class:`Fr700SimulatedBus` is
sans-IO (``receive(data, now) -> [Transmission]``), and every server of
:mod:`sj300_async.simulator` (:class:`~sj300_async.simulator.SimulatorEndpoint`,
:func:`~sj300_async.simulator.serve_tcp`, the pty and serial-device
servers, baud pacing) serves it as it is::

    bus = Fr700SimulatedBus(stations=range(4))          # CR, waiting-time field
    out = bus.receive(host_bytes, now)
    bus.drives[2].trip(now=now)
    bus.faults.corrupt_next(2)                           # its next reply's sum fails
"""

from __future__ import annotations

from ...fr700.codec import BadRequest, HostAnswer, HostRequest, RequestParser
from ._bus import Fr700SimulatedBus, Fr700SimulatorStats, corrupt, simulate
from ._command_line import COMMAND_LINE
from ._drive import DEFAULT_PROCESSING_S, Fr700SimulatedDrive
from ._parameters import PARAMETERS, ParameterSpec
from ._readings import FaultCode

__all__ = [
    "COMMAND_LINE",
    "DEFAULT_PROCESSING_S",
    "PARAMETERS",
    "BadRequest",
    "FaultCode",
    "Fr700SimulatedBus",
    "Fr700SimulatedDrive",
    "Fr700SimulatorStats",
    "HostAnswer",
    "HostRequest",
    "ParameterSpec",
    "RequestParser",
    "corrupt",
    "simulate",
]
