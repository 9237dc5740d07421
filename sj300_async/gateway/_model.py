"""What a gateway is configured to do: frozen dataclasses.

:mod:`._config` builds and validates a :class:`GatewayConfig` from a TOML
file (errors name the file, line and key) or from the command line's flags;
everything else in the gateway reads only these objects. Each northbound
owns its section and its configuration class (:mod:`._northbound`): the
core holds them by section name, without knowing them. Nothing here does
I/O.

Decisions (docs/GATEWAY.md has the user's view):

- Read-only unless a :class:`WriteGrant` names the drive: a grant lists the
  nodes it covers, the parameters they may have written (an allow-list of
  codes) and whether run/stop/frequency commands are allowed (``control``).
  A drive's permissions are the union of the grants that name it.
- Control needs a lease (:mod:`._lease`): ``lease_s`` and ``on_lapse`` are
  per line, because the action on lapse depends on the line (a broadcast
  stop exists on SJ300 lines only).
- Unit ids (Modbus units): unit = node + the protocol profile's offset
  (SJ300 node n is unit n; FR-700 station s is unit 100 + s); a line's
  ``unit_offset`` overrides it.
- The gateway's id names it to the outside (MQTT topics): the host name
  unless configured, its first label cut to the characters a topic level
  may hold (:func:`default_gateway_id`).
"""

from __future__ import annotations

import re
import socket
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final, Literal, get_args

from ..wire import LocalProtocolError
from .recorder._settings import RecorderConfig

__all__ = [
    "DEFAULT_LEASE_S",
    "DEFAULT_LOOP_LAG_LIMIT_S",
    "DEFAULT_STALE_AFTER_S",
    "LAPSE_ACTIONS",
    "LEASE_SCOPES",
    "UNIT_RANGE",
    "Endpoint",
    "GatewayConfig",
    "LapseAction",
    "LeaseScope",
    "LineConfig",
    "WriteGrant",
    "default_gateway_id",
    "parse_endpoint",
]

#: What a line's poll reads of each drive besides its parameters (the poller's reads).
PollRead = Literal["status", "monitor"]
POLL_READS: Final[tuple[PollRead, ...]] = get_args(PollRead)
#: What the gateway does when a control lease lapses.
LapseAction = Literal["stop", "broadcast_stop", "hold"]
LAPSE_ACTIONS: Final = get_args(LapseAction)
#: What ends a control lease besides its time running out (see LineConfig.lease_scope).
LeaseScope = Literal["client", "connection"]
LEASE_SCOPES: Final = get_args(LeaseScope)
#: Reads of data older than this fail with Modbus exception 0x0B.
DEFAULT_STALE_AFTER_S: Final = 5.0
#: The event loop's lag over which ``/healthz`` says the gateway is degraded: well past
#: the 200 ms the tests hold every attack to, so that one long collection of the
#: garbage collector's oldest generation is not called a fault, and well short of any
#: lease (seconds).
DEFAULT_LOOP_LAG_LIMIT_S: Final = 0.5
DEFAULT_LEASE_S: Final = 5.0
#: The Modbus unit ids a drive may have (0 is broadcast; 248..255 reserved).
UNIT_RANGE: Final = range(1, 248)


#: What a gateway id may not hold (MQTT wildcards and separators, among others).
_NOT_IN_ID: Final = re.compile(r"[^A-Za-z0-9_.-]+")


def default_gateway_id() -> str:
    """The host name's first label, cut to a topic level (``"gateway"`` if nothing is left)."""
    label = socket.gethostname().split(".", 1)[0]
    return _NOT_IN_ID.sub("-", label).strip("-") or "gateway"


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
    #: A registered protocol name (one with a profile).
    protocol: str
    nodes: tuple[int, ...]
    #: The poll plan: cycle interval, reads (``"status"``, ``"monitor"``) and
    #: parameters (normalised codes) read every cycle.
    interval_s: float = 0.5
    reads: tuple[PollRead, ...] = POLL_READS
    parameters: tuple[str, ...] = ()
    #: Seconds between two reads of a drive's trip history (0: never); it is
    #: also read when the drive's status turns to tripped. Only for a protocol
    #: whose profile reads trip histories (others ignore it).
    trips_interval_s: float = 30.0
    #: Seconds between two reads of a drive's set frequency (0: never), when it
    #: is not polled as a parameter (SJ300 F001): SCADA shows the setpoint next
    #: to the output frequency, so it is read by default, slower than the poll.
    #: Read at least twice per ``stale_after_s`` whatever this says, so the value
    #: a northbound serves never goes stale between two reads.
    setpoint_interval_s: float = 2.0
    #: Unit id = node + unit_offset.
    unit_offset: int = 0
    #: The response time-out per attempt (None: the bus's computed one).
    timeout_s: float | None = None
    grants: tuple[WriteGrant, ...] = ()
    lease_s: float = DEFAULT_LEASE_S
    on_lapse: LapseAction = "stop"
    #: ``"client"``: the lease lapses ``lease_s`` after the holder's last
    #: heartbeat; ``"connection"``: also the moment the connection it came
    #: by closes (docs/GATEWAY.md, "What the gateway guarantees").
    lease_scope: LeaseScope = "client"

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
class GatewayConfig:
    """A whole gateway: its lines and what it serves."""

    lines: tuple[LineConfig, ...]
    #: Each configured northbound's configuration, by its section name
    #: (``"modbus"``), in the order the northbound registry lists them.
    northbounds: Mapping[str, object] = field(default_factory=dict)
    stale_after_s: float = DEFAULT_STALE_AFTER_S
    #: A file the audit log is appended to, besides the ``sj300_async.gateway.audit`` logger.
    audit_log: Path | None = None
    #: ``/healthz`` says the gateway is degraded while the event loop lags more (._looplag).
    loop_lag_limit_s: float = DEFAULT_LOOP_LAG_LIMIT_S
    #: Where the configuration came from (a file name, or ``"<command line>"``).
    source: str = field(default="<command line>", compare=False)
    #: The gateway's name to the outside (an MQTT topic level; see the module docstring).
    gateway_id: str = field(default_factory=default_gateway_id)
    #: The trip recorder (``[recorder]``; :mod:`.recorder`): on, in memory, by default.
    recorder: RecorderConfig = field(default_factory=RecorderConfig)


_HOST: Final = re.compile(r"[A-Za-z0-9_.%:-]+\Z")


def parse_endpoint(text: str) -> Endpoint:
    """Parse a listening address: ``"HOST:PORT"``, ``"[::1]:502"`` or ``":502"`` (every interface).

    Port 0 asks the system for a free port.

    Raises:
        LocalProtocolError: not one of those forms, or a port outside 0..65535.
    """
    value = text.strip()
    if value.startswith("["):
        host, bracket, port = value[1:].partition("]:")
        if not bracket:
            raise LocalProtocolError(f"expected [IPV6]:PORT, got {text!r}")
    else:
        host, colon, port = value.rpartition(":")
        if not colon:
            raise LocalProtocolError(f"expected HOST:PORT, got {text!r}")
        if ":" in host:
            raise LocalProtocolError(f"put an IPv6 address in brackets: [{host}]:{port}")
        host = host or "0.0.0.0"
    if not _HOST.match(host):
        raise LocalProtocolError(f"bad host {host!r} in {text!r}")
    if not (port.isascii() and port.isdigit() and int(port) <= 65535):
        raise LocalProtocolError(f"port must be 0..65535, got {port!r}")
    return Endpoint(host, int(port))
