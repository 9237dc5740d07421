"""The MQTT contract: topics and payloads, shared by the gateway's bridge and the fleet subscriber.

Sans-IO (no client here): what goes where, and how a drive's state is
written as JSON and read back. docs/GATEWAY.md prints the same layout.

Topics (``prefix`` defaults to ``sj300``; ``gateway`` is the gateway's
``--id``, ``line`` the line's name, ``node`` the drive's address)::

    <prefix>/<gateway>/availability                 "online" / "offline" (retained; last will)
    <prefix>/<gateway>/<line>/<node>/state          JSON, retained, one per poll
    <prefix>/<gateway>/<line>/<node>/availability   "online" / "offline" (retained)
    <prefix>/<gateway>/<line>/<node>/set/<what>     commands (never retained)
    <prefix>/<gateway>/<line>/<node>/error          refused commands (JSON, not retained)
    homeassistant/<component>/<node_id>/<object_id>/config   discovery (retained)

``<what>`` is ``lease`` (any payload: take or renew the control lease),
``command`` (``run_forward``, ``run_reverse``, ``stop``), ``frequency_hz``
(a number) or a parameter code (``A004``, ``Pr.7``: a number in the
parameter's unit). One topic per thing written is what Home Assistant's
number, select and button entities publish to.

Decisions: names may hold only ``[A-Za-z0-9_.-]`` (no MQTT wildcards or
separators; the gateway's configuration refuses others); the state's keys
carry their units (``output_frequency_hz``); a value not read yet, or stale,
is ``null`` rather than left out, so that a consumer's template never
fails on a missing key; ``time`` is Unix time in seconds (a consumer on
another machine cannot use the gateway's event-loop clock). The state in
words (``state``) and the trip's meaning (``trip_meaning``) travel with
the values, worked out once by the drive's profile: a consumer never
decodes a protocol's status codes to show them.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Final

from .. import compact_json

__all__ = [
    "AVAILABLE",
    "COMMANDS",
    "DEFAULT_PREFIX",
    "UNAVAILABLE",
    "StateMessage",
    "Topics",
    "parse_node",
    "parse_state_topic",
]

DEFAULT_PREFIX: Final = "sj300"
DISCOVERY_PREFIX: Final = "homeassistant"
AVAILABLE: Final = "online"
UNAVAILABLE: Final = "offline"
#: The payloads of ``…/set/command``.
COMMANDS: Final = ("run_forward", "run_reverse", "stop")


@dataclass(frozen=True, slots=True)
class Topics:
    """The topics of one gateway (see the module docstring)."""

    gateway: str
    prefix: str = DEFAULT_PREFIX

    @property
    def availability(self) -> str:
        return f"{self.prefix}/{self.gateway}/availability"

    def drive(self, line: str, node: int) -> str:
        return f"{self.prefix}/{self.gateway}/{line}/{node}"

    def state(self, line: str, node: int) -> str:
        return f"{self.drive(line, node)}/state"

    def drive_availability(self, line: str, node: int) -> str:
        return f"{self.drive(line, node)}/availability"

    def command(self, line: str, node: int, what: str) -> str:
        return f"{self.drive(line, node)}/set/{what}"

    def error(self, line: str, node: int) -> str:
        return f"{self.drive(line, node)}/error"

    def event(self, line: str, node: int) -> str:
        """The drive's events (:mod:`._drive_events`), not retained."""
        return f"{self.drive(line, node)}/event"

    def trip(self, line: str, node: int) -> str:
        """The drive's trip records as they are kept (:mod:`._drive_events`), not retained."""
        return f"{self.drive(line, node)}/trip"

    @property
    def command_filter(self) -> str:
        """What the bridge subscribes to for commands."""
        return f"{self.prefix}/{self.gateway}/+/+/set/+"

    def parse_command(self, topic: str) -> tuple[str, int, str] | None:
        """``(line, node, what)`` of a command topic of this gateway, else None."""
        parts = topic.split("/")
        head = [*self.prefix.split("/"), self.gateway]
        if len(parts) != len(head) + 4 or parts[: len(head)] != head or parts[-2] != "set":
            return None
        line, node, _, what = parts[len(head) :]
        number = parse_node(node)
        return None if number is None else (line, number, what)


def parse_node(level: str) -> int | None:
    """A topic level's node number, else None. ASCII digits only, and few: ``str.isdigit``
    takes ``²``, which ``int`` refuses, and ``int`` refuses 4,301 digits (a junk topic's
    ValueError ended the bridge's receiver, and the connection, at every delivery)."""
    return int(level) if len(level) <= 9 and level.isascii() and level.isdigit() else None


def parse_state_topic(topic: str, prefix: str = DEFAULT_PREFIX) -> tuple[str, str, int] | None:
    """``(gateway, line, node)`` of any gateway's state topic under *prefix*, else None."""
    head = prefix.split("/")
    parts = topic.split("/")
    if len(parts) != len(head) + 4 or parts[: len(head)] != head or parts[-1] != "state":
        return None
    gateway, line, node = parts[len(head) : len(head) + 3]
    number = parse_node(node)
    return None if number is None else (gateway, line, number)


@dataclass(frozen=True, slots=True)
class StateMessage:
    """One drive's state as published (the JSON of ``…/state``)."""

    gateway: str
    line: str
    node: int
    protocol: str
    #: Unix time of the poll that produced it, in seconds.
    time: float
    online: bool
    output_frequency_hz: float | None = None
    output_current_a: float | None = None
    output_voltage_v: float | None = None
    #: ``"stop"``, ``"forward"``, ``"reverse"``, or None when unknown.
    direction: str | None = None
    running: bool | None = None
    tripped: bool | None = None
    #: The present trip's code as the drive's display shows it (``"E07"``), when tripped
    #: and known.
    trip: str | None = None
    set_frequency_hz: float | None = None
    output_torque_percent: float | None = None
    power_kw: float | None = None
    #: Status as text: SJ300 ``{"a": "RUNNING", "b": ..., "c": ...}``, FR-700 ``{"bits": 11}``.
    status: Mapping[str, Any] | None = None
    #: Polled parameters in their units, by code; None when stale or unavailable.
    parameters: Mapping[str, float | None] = field(default_factory=dict)
    #: The state in words (``stopped``, ``accelerating``, ``tripped``), None when unknown.
    state: str | None = None
    #: What the present trip means (``"over-voltage"``), None when unknown or not tripped.
    trip_meaning: str | None = None
    #: A lapsed control lease's stop is not confirmed yet (docs/GATEWAY.md, the control lease).
    lapse_pending: bool = False

    def to_json(self) -> bytes:
        """The payload: compact, keys sorted (needs the gateway extra: orjson)."""
        body = {name: getattr(self, name) for name in self.__slots__}
        body["parameters"] = dict(self.parameters)
        body["status"] = None if self.status is None else dict(self.status)
        return compact_json(body, sort_keys=True)

    @classmethod
    def from_json(cls, payload: bytes | str) -> StateMessage:
        """Read a payload back.

        Raises:
            ValueError: not JSON, or not a state message (missing or mistyped keys).
        """
        try:
            body = json.loads(payload)
        except json.JSONDecodeError as exc:
            raise ValueError(f"not JSON: {exc}") from None
        if not isinstance(body, dict):
            raise ValueError("a state message is a JSON object")
        known = {name: body[name] for name in cls.__slots__ if name in body}
        try:
            message = cls(**known)
        except TypeError as exc:
            raise ValueError(f"not a state message: {exc}") from None
        if not isinstance(message.node, int) or not isinstance(message.gateway, str):
            raise ValueError("a state message names its gateway (text) and node (number)")
        return message
