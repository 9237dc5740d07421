"""``sj300 monitor --json``: one record shape for a drive sample, from a bus or from a broker.

A record is one drive at one sample, whichever way the monitor got it:
polled on a bus (:mod:`._board` builds it from the drive's
:class:`~sj300_async.profiles.DriveSnapshot`) or received from a gateway's
MQTT state (:mod:`._fleet` builds it from the
:class:`~sj300_async.gateway.mqtt.StateMessage`). docs/guide/cli.md prints
the field table.

Decisions:

- The names are the drive model's (``DriveSnapshot``), which the MQTT
  state already uses: units in the names (``output_frequency_hz``),
  ``state`` and ``trip_meaning`` as the profile words them, ``direction``
  as ``"stop"`` / ``"forward"`` / ``"reverse"``, ``status`` as the protocol
  words it (SJ300 ``{"a": "RUNNING", "b": ..., "c": ...}``, FR-700
  ``{"bits": 11}``), ``parameters`` in their unit by code (null: refused
  or stale).
- One time, ``time``: the sample's, in Unix seconds (the poll's end on a
  bus, the gateway's poll on MQTT), never the time it was printed; an
  event loop's clock means nothing outside its process.
- What only one source knows is null on the other, never left out: a
  direct bus has no ``gateway``, ``gateway_online`` or ``lapse_pending``;
  a broker gives no ``error`` or ``latency_s``. ``line`` is the gateway's
  line, or on a bus the bus itself (its description, as the snapshot's).
- ``online``: the drive answers (it has answered, and its poller has not
  set it aside as offline), the gateway's ``online`` on MQTT.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

from ..wire import Direction
from ._output import jsonable

__all__ = ["FIELDS", "DriveRecord", "direction_word"]


@dataclass(frozen=True, slots=True)
class DriveRecord:
    """One drive at one sample, as ``sj300 monitor --json`` prints it (see the module)."""

    #: Unix time of the sample, in seconds.
    time: float
    #: The gateway's id (its ``--id``); None on a direct bus.
    gateway: str | None
    #: The gateway's line; on a direct bus, the bus (``tcp://127.0.0.1:4001``).
    line: str
    #: The drive's address on its line (a node; an FR-700 station).
    node: int
    #: The drive's protocol (``sj300``, ``fr700``).
    protocol: str
    #: The drive answers.
    online: bool
    #: The state in words (``stopped``, ``accelerating``, ``tripped``); None: unknown.
    state: str | None
    running: bool | None
    tripped: bool | None
    #: The present trip's code as the drive's display shows it (``E07``), when known.
    trip: str | None
    #: What it means (``over-voltage``), when known.
    trip_meaning: str | None
    #: ``stop``, ``forward``, ``reverse``; None: unknown.
    direction: str | None
    output_frequency_hz: float | None
    set_frequency_hz: float | None
    output_current_a: float | None
    output_voltage_v: float | None
    output_torque_percent: float | None
    power_kw: float | None
    #: The status as the protocol words it; None: not read.
    status: Mapping[str, Any] | None
    #: Polled parameters in their unit by code (None: refused, or stale on MQTT).
    parameters: Mapping[str, float | None]
    #: A bus: the poll's error (None: every read succeeded). MQTT: None.
    error: str | None = None
    #: A bus: the mean time per read of the poll, in seconds. MQTT: None.
    latency_s: float | None = None
    #: MQTT: False once the gateway's availability says offline (its states are then
    #: nobody's news). A bus: None.
    gateway_online: bool | None = None
    #: MQTT: a lapsed control lease's stop is not confirmed yet. A bus: None.
    lapse_pending: bool | None = None

    def as_json(self) -> dict[str, Any]:
        """The record as printed: every field, in this order."""
        body: dict[str, Any] = jsonable(self)
        return body


#: The record's field names, in the printed order.
FIELDS: Final = tuple(f.name for f in dataclasses.fields(DriveRecord))


_DIRECTIONS: Final = {
    Direction.STOP: "stop",
    Direction.FORWARD: "forward",
    Direction.REVERSE: "reverse",
}


def direction_word(direction: Direction | None) -> str | None:
    """``stop``, ``forward``, ``reverse`` (the MQTT state's words); None when unknown."""
    return None if direction is None else _DIRECTIONS.get(direction)
