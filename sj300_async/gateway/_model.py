"""What a gateway is configured to do: frozen dataclasses.

:mod:`._config` builds and validates a :class:`GatewayConfig` from a TOML
file (errors name the file, line and key) or from the command line's flags;
everything else in the gateway reads only these objects. Nothing here does
I/O.

Decisions (docs/GATEWAY.md has the user's view):

- Read-only unless a :class:`WriteGrant` names the drive: a grant lists the
  nodes it covers, the parameters they may have written (an allow-list of
  codes) and whether run/stop/frequency commands are allowed (``control``).
  A drive's permissions are the union of the grants that name it.
- Control needs a lease (:mod:`._lease`): ``lease_s`` and ``on_lapse`` are
  per line, because the action on lapse depends on the line (a broadcast
  stop exists on SJ300 lines only).
- Modbus unit ids: SJ300 node n is unit n; FR-700 station s is unit 100 + s
  (station 0 exists, unit 0 is Modbus's broadcast, and the two protocols'
  defaults never collide). ``unit_offset`` overrides: unit = node + offset.
- MQTT (:class:`MqttConfig`, optional): the gateway is known on the broker
  by its id, the host name unless configured (its first label, cut to the
  characters a topic level may hold: :func:`default_gateway_id`).
"""

from __future__ import annotations

import re
import socket
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final, Literal, get_args

__all__ = [
    "DEFAULT_LEASE_S",
    "DEFAULT_STALE_AFTER_S",
    "LAPSE_ACTIONS",
    "UNIT_RANGE",
    "Endpoint",
    "GatewayConfig",
    "LapseAction",
    "LineConfig",
    "MqttConfig",
    "WriteGrant",
    "default_gateway_id",
    "default_unit_offset",
]

#: What the gateway does when a control lease lapses.
LapseAction = Literal["stop", "broadcast_stop", "hold"]
LAPSE_ACTIONS: Final = get_args(LapseAction)
#: Reads of data older than this fail with Modbus exception 0x0B.
DEFAULT_STALE_AFTER_S: Final = 5.0
DEFAULT_LEASE_S: Final = 5.0
#: The Modbus unit ids a drive may have (0 is broadcast; 248..255 reserved).
UNIT_RANGE: Final = range(1, 248)


#: What a gateway id may not hold (MQTT wildcards and separators, among others).
_NOT_IN_ID: Final = re.compile(r"[^A-Za-z0-9_.-]+")


def default_gateway_id() -> str:
    """The host name's first label, cut to a topic level (``"gateway"`` if nothing is left)."""
    label = socket.gethostname().split(".", 1)[0]
    return _NOT_IN_ID.sub("-", label).strip("-") or "gateway"


def default_unit_offset(protocol: str) -> int:
    """Unit id = node + this, unless the line says otherwise (see the module docstring)."""
    return 100 if protocol == "fr700" else 0


@dataclass(frozen=True, slots=True)
class Endpoint:
    """A TCP listening address."""

    host: str
    port: int

    def __str__(self) -> str:
        return f"[{self.host}]:{self.port}" if ":" in self.host else f"{self.host}:{self.port}"


@dataclass(frozen=True, slots=True)
class WriteGrant:
    """Writes allowed to some drives of a line (see the module docstring)."""

    #: The nodes this grant covers.
    nodes: frozenset[int]
    #: Parameter codes these drives may have written, normalised by the
    #: line's dialect (``"A004"``, ``"Pr.7"``).
    parameters: frozenset[str] = frozenset()
    #: Run, stop, direction and set frequency (each needs the control lease).
    control: bool = False


@dataclass(frozen=True, slots=True)
class LineConfig:
    """One line the gateway owns: where it is, what it polls, what may be written."""

    #: The line's name in metrics, logs and the audit log.
    name: str
    url: str
    #: A registered protocol name (``"sj300"``, ``"fr700"``).
    protocol: str
    nodes: tuple[int, ...]
    #: The poll plan: cycle interval, reads (``"status"``, ``"monitor"``) and
    #: parameters (normalised codes) read every cycle.
    interval_s: float = 0.5
    reads: tuple[str, ...] = ("status", "monitor")
    parameters: tuple[str, ...] = ()
    #: Seconds between two reads of a drive's trip history (0: never); it is
    #: also read when the drive's status turns to tripped. SJ300 only (an
    #: FR-700 line ignores it: its drive class reads no alarm history yet).
    trips_interval_s: float = 30.0
    #: Unit id = node + unit_offset.
    unit_offset: int = 0
    #: The response time-out per attempt (None: the bus's computed one).
    timeout_s: float | None = None
    grants: tuple[WriteGrant, ...] = ()
    lease_s: float = DEFAULT_LEASE_S
    on_lapse: LapseAction = "stop"

    def unit(self, node: int) -> int:
        """The Modbus unit id of *node*."""
        return node + self.unit_offset

    def writable_parameters(self, node: int) -> frozenset[str]:
        """The parameter codes *node* may have written (empty: none)."""
        out: frozenset[str] = frozenset()
        for grant in self.grants:
            if node in grant.nodes:
                out |= grant.parameters
        return out

    def control_allowed(self, node: int) -> bool:
        """True when *node* may get run/stop/frequency commands (with the lease)."""
        return any(grant.control and node in grant.nodes for grant in self.grants)


@dataclass(frozen=True, slots=True)
class MqttConfig:
    """The MQTT broker the gateway publishes to (docs/GATEWAY.md, "MQTT")."""

    host: str
    port: int
    #: TLS: an ``mqtts://`` URL, or a ``tls_ca`` given.
    tls: bool = False
    #: The MQTT client id (the configuration's default: ``sj300-<gateway id>``).
    client_id: str = "sj300"
    username: str | None = None
    password: str | None = field(default=None, repr=False)
    #: The CA certificates that verify the broker (None: the system's).
    tls_ca: Path | None = None
    #: The first topic level(s): ``<prefix>/<gateway id>/...``.
    prefix: str = "sj300"
    #: The QoS of everything published and subscribed (0 or 1).
    qos: int = 1
    #: Home Assistant's MQTT discovery: configs published, and republished on its birth.
    discovery: bool = True
    discovery_prefix: str = "homeassistant"
    #: The MQTT keepalive: the broker publishes the last will ("offline") about
    #: 1.5 keepalives after the gateway last spoke (plus its own check interval).
    keepalive_s: int = 30

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'mqtts' if self.tls else 'mqtt'}://{host}:{self.port}"


@dataclass(frozen=True, slots=True)
class GatewayConfig:
    """A whole gateway: its lines and what it serves."""

    lines: tuple[LineConfig, ...]
    #: Where the Modbus TCP server listens (None: no Modbus server).
    modbus: Endpoint | None = None
    #: Where /metrics and /healthz are served (None: not served).
    metrics: Endpoint | None = None
    stale_after_s: float = DEFAULT_STALE_AFTER_S
    #: A file the audit log is appended to, besides the ``sj300_async.gateway.audit`` logger.
    audit_log: Path | None = None
    #: Where the configuration came from (a file name, or ``"<command line>"``).
    source: str = field(default="<command line>", compare=False)
    #: The MQTT broker (None: no MQTT).
    mqtt: MqttConfig | None = None
    #: The gateway's name on MQTT (a topic level; see the module docstring).
    gateway_id: str = field(default_factory=default_gateway_id)
