"""The gateway on MQTT: each drive's state and availability, Home Assistant discovery, commands.

:class:`MqttBridge` is started by the :class:`~._gateway.Gateway` when the
configuration has ``[mqtt]``. It publishes what :mod:`._mqtt_topics` (the
contract, shared with the fleet view) lays out:

- ``<prefix>/<gw>/availability``: ``online`` (retained) once connected; the
  last will says ``offline`` when the broker loses the gateway (a crash: at
  once; a frozen process, a cut cable: 1.5 ``keepalive_s`` later, plus the
  broker's own check interval); a clean stop says
  ``offline`` itself before disconnecting: the drives are no longer served.
- ``…/<line>/<node>/state``: one retained :class:`~._mqtt_topics.StateMessage`
  per drive per poll, from the drive's :class:`~._state.DriveState`.
- ``…/<line>/<node>/availability``: ``online`` while the poller hears the
  drive (and it has answered at least once), published when that changes.
- Home Assistant discovery (``discovery = true``): sensors per drive, and
  for a drive whose configuration grants control, a number (set frequency)
  and buttons (run forward, run reverse, stop, the lease heartbeat).
- ``…/<line>/<node>/set/<what>``: commands, judged and carried out by the
  line's :class:`~._control.Controller` exactly like Modbus writes (allow-
  list, lease, validation, read-back, audit). A refusal is answered on
  ``…/<line>/<node>/error`` (JSON, not retained).

Decisions:

- **One identity for MQTT.** MQTT carries no client identity a gateway can
  trust, so every command comes from client ``"mqtt"``: whoever may publish
  to the ``set`` topics (the broker's ACL decides) shares one control lease,
  and a Modbus client holding a drive's lease makes MQTT commands to it
  busy (and the other way round).
- **Never a stale command.** A message with the retain flag is refused: the
  broker stored it, nobody sent it now (a retained "run_forward" would
  start a motor at every reconnect). Commands are taken only while
  connected, with a clean session (nothing queued for the gateway while it
  was away); one received but not started before the connection broke is
  discarded, counted, never carried out later.
- **Never block the poller.** :meth:`MqttBridge.on_sample` only builds the
  message and leaves it in the outbox, which holds at most one state and
  one availability per drive: a newer one replaces the one not sent yet
  (counted in ``BridgeStats.replaced``), so a broker that is down or slow
  costs memory bounded by the number of drives, and the state that reaches
  it is always the latest. The bridge's task drains the outbox.
- **Values are null when stale.** A value is published only when younger
  than ``stale_after_s`` (the rule of the Modbus reads); ``trip`` is the
  latest trip record's code only when the drive is tripped and the trip
  history was read after the trip was seen (the record read before it
  would name the previous trip).
- **Reconnecting**: after a loss, back off 0.5 s doubling to 30 s (reset by
  a good connection), then republish availability, discovery and every
  drive's latest state (the broker may have restarted without its retained
  messages). A loss is logged once, at WARNING; the attempts after it at
  DEBUG. The Modbus side does not depend on the broker.
- Commands to one drive are carried out in order (a lease, then a
  frequency); each drive has its own queue, so a drive that does not
  answer delays only its own commands, never another drive's heartbeat.
- Discovery uses ``default_entity_id``, not ``object_id``: Home Assistant
  deprecated ``object_id`` in 2025.10 and stopped honouring it in 2026.4.
  A discovery node id holds only ``[A-Za-z0-9_-]``, so a line name's ``.``
  becomes ``_`` there: two lines named ``a.b`` and ``a_b`` would share
  their drives' node ids (name lines apart).
- The bridge publishes with the configured QoS and waits for each batch's
  acknowledgements (at most ``MAX_IN_FLIGHT`` at once) before the next: a
  slow broker makes the outbox coalesce, never grow.

Nothing is dropped silently: every replaced, lost or discarded message and
every refused command is counted in :attr:`MqttBridge.stats` and logged at
DEBUG (refusals also in the audit log).
"""

from __future__ import annotations

import asyncio
import collections
import functools
import json
import logging
import math
import re
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, Protocol

import aiomqtt

from .._poller import Sample
from .._version import __version__
from ..bus._registry import get_dialect
from ..fr700 import Fr700Monitor, Fr700Status
from ..sj300 import InverterStatus, MonitorData
from ._control import MAX_FREQUENCY_HZ, Controller, raw_of, value_of
from ._model import LineConfig, MqttConfig
from ._mqtt_topics import AVAILABLE, UNAVAILABLE, StateMessage, Topics
from ._registers import Command, Exc, Heartbeat, ParameterWrite, SetFrequency, WriteRequest
from ._state import DriveState

__all__ = ["CLIENT", "BridgeStats", "BridgedLine", "MqttBridge", "discovery", "state_message"]

_log = logging.getLogger("sj300_async.gateway.mqtt")

#: The client every MQTT command comes from (see the module docstring).
CLIENT: Final = "mqtt"
BACKOFF_FIRST_S: Final = 0.5
BACKOFF_MAX_S: Final = 30.0
#: Error replies waiting to be sent, at most (the oldest is dropped, counted).
MAX_ERRORS: Final = 100
#: Commands waiting for one drive, at most (more are refused: DEVICE_BUSY).
MAX_COMMANDS: Final = 16
#: Publishes in flight at once (paho queues the rest; aiomqtt warns past its threshold).
MAX_IN_FLIGHT: Final = 32
#: Messages paho may hold for a socket that does not take them.
MAX_QUEUED: Final = 1000
#: How long a clean stop waits for a write under way, and for its last publishes.
CLOSE_TIMEOUT_S: Final = 3.0
#: How often a task that lost its cancellation is cancelled again (see _cancel_and_wait).
CANCEL_AGAIN_S: Final = 0.1
#: The payloads of ``…/set/command`` → the Modbus register's code (0 stop, 1 forward, 2 reverse).
_COMMANDS: Final = {"stop": 0, "run_forward": 1, "run_reverse": 2}
_MODELS: Final = {"sj300": ("SJ300", "Hitachi"), "fr700": ("FR-700", "Mitsubishi Electric")}
_NOT_IN_NODE_ID: Final = re.compile(r"[^A-Za-z0-9_-]")
_NOT_IN_ENTITY_ID: Final = re.compile(r"[^a-z0-9_]")

Key = tuple[str, int]


class BridgedLine(Protocol):
    """What the bridge needs of a line (the gateway's :class:`~._gateway.GatewayLine`)."""

    @property
    def config(self) -> LineConfig: ...
    @property
    def controller(self) -> Controller: ...
    @property
    def states(self) -> dict[int, DriveState]: ...


@dataclass
class BridgeStats:
    """What the bridge did (see the module docstring: nothing is dropped silently)."""

    connects: int = 0
    #: Connections lost (each logged once at WARNING).
    losses: int = 0
    #: Messages the broker took (QoS 1: acknowledged).
    published: int = 0
    #: Messages not confirmed: being sent when the connection broke or the
    #: bridge stopped (some may have reached the broker), or still waiting at
    #: the stop. States and availability are republished on reconnect; error
    #: replies are not.
    lost: int = 0
    #: Samples handed to the bridge, per drive.
    samples: collections.Counter[Key] = field(default_factory=collections.Counter)
    #: State messages published, per drive.
    states: collections.Counter[Key] = field(default_factory=collections.Counter)
    #: State messages replaced by a newer one before they were sent, per drive.
    replaced: collections.Counter[Key] = field(default_factory=collections.Counter)
    #: Error replies dropped: more than MAX_ERRORS were waiting.
    errors_dropped: int = 0
    #: Command messages received, refused, and discarded (received but not
    #: started before the connection they came on was lost).
    commands: int = 0
    refused: int = 0
    discarded: int = 0
    #: Messages on the command topics that name no drive of this gateway.
    ignored: int = 0


@dataclass(frozen=True, slots=True)
class _Out:
    """One message to publish."""

    topic: str
    payload: bytes
    retain: bool
    #: The drive of a state message (counted per drive), else None.
    drive: Key | None = None


@dataclass(frozen=True, slots=True)
class _Drive:
    line: BridgedLine
    state: DriveState


# -- the messages, sans-IO ----------------------------------------------------------------------


def state_message(
    gateway: str,
    state: DriveState,
    *,
    now: float,
    wall: float,
    stale_after_s: float,
    tripped_since: float | None = None,
) -> StateMessage:
    """*state* as published: values younger than *stale_after_s* at loop time *now*, else null.

    *wall* is the Unix time the message is for; *tripped_since* the loop
    time the drive was first seen tripped (its trip code is known only from
    a trip history read after that).
    """

    def fresh(at: float) -> bool:
        return now - at <= stale_after_s

    status = state.status if fresh(state.status_at) else None
    monitor = state.monitor if fresh(state.monitor_at) else None
    running: bool | None = None
    tripped: bool | None = None
    direction: str | None = None
    status_text: dict[str, Any] | None = None
    if isinstance(status, InverterStatus):
        running, tripped = status.b.value == 1, status.tripped  # StatusB.RUNNING
        status_text = {"a": status.a.name, "b": status.b.name, "c": status.c.name}
    elif isinstance(status, Fr700Status):
        running, tripped = status.running, status.tripped
        status_text = {"bits": int(status.bits)}
        direction = "reverse" if status.reverse else "forward" if running else "stop"
    sj300 = monitor if isinstance(monitor, MonitorData) else None
    if sj300 is not None:
        direction = {0: "stop", 1: "forward", 2: "reverse"}.get(int(sj300.direction))
    trip = None
    trips = state.trips
    if (
        tripped
        and trips is not None
        and trips.records
        and not trips.records[0].is_empty
        and tripped_since is not None
        and state.trips_at >= tripped_since
    ):
        trip = trips.records[0].error_code
    parameters = {
        code: value_of(state.protocol, code, raw)
        for code, raw in state.parameters.items()
        if fresh(state.parameters_at.get(code, -math.inf))
    }
    any_monitor = monitor if isinstance(monitor, MonitorData | Fr700Monitor) else None
    return StateMessage(
        gateway=gateway,
        line=state.line,
        node=state.node,
        protocol=state.protocol,
        time=wall,
        online=_available(state),
        output_frequency_hz=None if any_monitor is None else any_monitor.output_frequency_hz,
        output_current_a=None if any_monitor is None else any_monitor.output_current_a,
        output_voltage_v=None if any_monitor is None else any_monitor.output_voltage_v,
        direction=direction,
        running=running,
        tripped=tripped,
        trip=trip,
        set_frequency_hz=state.set_frequency_hz if fresh(state.set_frequency_at) else None,
        output_torque_percent=None if sj300 is None else float(sj300.output_torque_percent),
        power_kw=None if sj300 is None else sj300.power_kw,
        status=status_text,
        parameters=parameters,
    )


def _available(state: DriveState) -> bool:
    """The poller's verdict, and the drive has answered (a drive starts "online" unheard)."""
    return state.online and state.last_ok is not None


def node_id(*parts: object) -> str:
    """A Home Assistant discovery node id: ``[A-Za-z0-9_-]`` only."""
    return _NOT_IN_NODE_ID.sub("_", "_".join(map(str, parts)))


#: The sensors of every drive: object id, name, state key, unit, device class.
_SENSORS: Final = (
    ("output_frequency", "Output frequency", "output_frequency_hz", "Hz", "frequency"),
    ("output_current", "Output current", "output_current_a", "A", "current"),
    ("output_voltage", "Output voltage", "output_voltage_v", "V", "voltage"),
)
_SJ300_SENSORS: Final = (
    ("power", "Power", "power_kw", "kW", "power"),
    ("output_torque", "Output torque", "output_torque_percent", "%", None),
)
# Home Assistant's MQTT sensor takes the text "None" as "unknown": a stale
# value (null) shows as unknown, not as 0 or as an error.
_STATUS_TEMPLATE: Final = (
    "{% if value_json.running is none %}None"
    "{% elif value_json.tripped %}tripped"
    "{% elif value_json.running %}running"
    "{% if value_json.direction in ['forward', 'reverse'] %} {{ value_json.direction }}{% endif %}"
    "{% else %}stopped{% endif %}"
)
_TRIP_TEMPLATE: Final = (
    "{% if value_json.tripped is none %}None"
    "{% elif value_json.tripped %}{{ value_json.trip or 'tripped' }}"
    "{% else %}ok{% endif %}"
)
_BUTTONS: Final = (
    ("run_forward", "Run forward", "command", "run_forward"),
    ("run_reverse", "Run reverse", "command", "run_reverse"),
    ("stop", "Stop", "command", "stop"),
    ("lease", "Control lease heartbeat", "lease", "renew"),
)


def discovery(
    config: MqttConfig, topics: Topics, lines: Sequence[LineConfig]
) -> Iterator[tuple[str, dict[str, Any]]]:
    """Every Home Assistant discovery config: ``(topic, payload)``.

    The gateway is a device of its own (a connectivity sensor: what its
    availability says), and each drive's device names it as ``via_device``.
    Every drive entity is available when both the gateway and the drive are
    (``availability_mode: all``).
    """
    prefix, gateway = config.discovery_prefix, topics.gateway
    origin = {"name": "sj300-async", "sw_version": __version__}
    gateway_device = node_id("sj300", gateway)
    yield (
        f"{prefix}/binary_sensor/{gateway_device}/connectivity/config",
        {
            "name": "Connectivity",
            "unique_id": f"{gateway_device}_connectivity",
            "default_entity_id": _entity_id("binary_sensor", f"{gateway_device}_connectivity"),
            "device": {
                "identifiers": [gateway_device],
                "name": f"sj300 gateway {gateway}",
                "model": "sj300 gateway",
                "manufacturer": "sj300-async",
                "sw_version": __version__,
            },
            "origin": origin,
            "state_topic": topics.availability,
            "payload_on": AVAILABLE,
            "payload_off": UNAVAILABLE,
            "device_class": "connectivity",
            "entity_category": "diagnostic",
            "qos": config.qos,
        },
    )
    for line in lines:
        model, manufacturer = _MODELS.get(line.protocol, (line.protocol, "unknown"))
        noun = get_dialect(line.protocol).node_noun
        for node in line.nodes:
            drive = node_id("sj300", gateway, line.name, node)
            state_topic = topics.state(line.name, node)
            common: dict[str, Any] = {
                "device": {
                    "identifiers": [drive],
                    "name": f"{line.name} {noun} {node}",
                    "model": model,
                    "manufacturer": manufacturer,
                    "via_device": gateway_device,
                },
                "origin": origin,
                "availability": [
                    {"topic": topics.availability},
                    {"topic": topics.drive_availability(line.name, node)},
                ],
                "availability_mode": "all",
                "payload_available": AVAILABLE,
                "payload_not_available": UNAVAILABLE,
                "qos": config.qos,
            }

            entity = functools.partial(_entity, prefix, drive, common)

            sensors = _SENSORS + (_SJ300_SENSORS if line.protocol == "sj300" else ())
            for object_id, name, key, unit, device_class in sensors:
                keys: dict[str, Any] = {
                    "state_topic": state_topic,
                    "value_template": f"{{{{ value_json.{key} }}}}",
                    "unit_of_measurement": unit,
                    "state_class": "measurement",
                }
                if device_class is not None:
                    keys["device_class"] = device_class
                yield entity("sensor", object_id, name, **keys)
            yield entity(
                "sensor",
                "status",
                "Status",
                state_topic=state_topic,
                value_template=_STATUS_TEMPLATE,
                json_attributes_topic=state_topic,
                json_attributes_template="{{ (value_json.status or {}) | tojson }}",
            )
            if line.protocol == "sj300":  # FR-700 drives have no trip history read (yet)
                yield entity(
                    "sensor", "trip", "Trip", state_topic=state_topic, value_template=_TRIP_TEMPLATE
                )
            if not line.control_allowed(node):
                continue
            yield entity(
                "number",
                "set_frequency",
                "Set frequency",
                command_topic=topics.command(line.name, node, "frequency_hz"),
                state_topic=state_topic,
                value_template="{{ value_json.set_frequency_hz }}",
                min=0,
                max=MAX_FREQUENCY_HZ,
                step=0.01,
                mode="box",
                unit_of_measurement="Hz",
                device_class="frequency",
                retain=False,
            )
            for object_id, name, what, payload in _BUTTONS:
                yield entity(
                    "button",
                    object_id,
                    name,
                    command_topic=topics.command(line.name, node, what),
                    payload_press=payload,
                    retain=False,
                )


def _entity(
    prefix: str,
    drive: str,
    common: dict[str, Any],
    component: str,
    object_id: str,
    name: str,
    **keys: Any,
) -> tuple[str, dict[str, Any]]:
    """One discovery config of a drive's entity: its topic and payload."""
    unique = f"{drive}_{object_id}"
    body = {
        "name": name,
        "unique_id": unique,
        "default_entity_id": _entity_id(component, unique),
        **common,
        **keys,
    }
    return f"{prefix}/{component}/{drive}/{object_id}/config", body


def _entity_id(component: str, unique_id: str) -> str:
    """``sensor.sj300_gw1_hall_a_3_power``: an entity id holds only ``[a-z0-9_]``."""
    return f"{component}.{_NOT_IN_ENTITY_ID.sub('_', unique_id.lower())}"


def _number(text: str) -> float | None:
    """A finite number, else None."""
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _request(protocol: str, what: str, payload: bytes) -> WriteRequest | tuple[Exc, str]:
    """The write a command asks for, or its refusal (nothing judged yet)."""
    if what == "lease":
        return Heartbeat()  # any payload
    try:
        text = payload.decode("utf-8").strip()
    except UnicodeDecodeError:
        return Exc.ILLEGAL_VALUE, "the payload is not UTF-8 text"
    if what == "command":
        if text not in _COMMANDS:
            return Exc.ILLEGAL_VALUE, f"expected run_forward, run_reverse or stop, got {text!r}"
        return Command(_COMMANDS[text])
    if what == "frequency_hz":
        hz = _number(text)
        if hz is None:
            return Exc.ILLEGAL_VALUE, f"expected a number of Hz, got {text!r}"
        if abs(round(hz * 100) - hz * 100) > 1e-6:  # the set frequency's step, on both protocols
            return Exc.ILLEGAL_VALUE, f"{text} Hz is finer than 0.01 Hz"
        return SetFrequency(hz)
    code = get_dialect(protocol).parameter_code(what)
    if code is None:
        return (
            Exc.ILLEGAL_ADDRESS,
            f"no such command or parameter {what!r} "
            "(use lease, command, frequency_hz or a parameter code)",
        )
    value = _number(text)
    if value is None:
        return Exc.ILLEGAL_VALUE, f"expected a number in {code}'s unit, got {text!r}"
    try:
        raw = raw_of(protocol, code, value)
    except (OverflowError, ValueError):
        return Exc.ILLEGAL_VALUE, f"{text} is outside {code}'s range"
    # raw_of rounds what its step cannot hold (Modbus cannot send it anyway);
    # a number on MQTT can be finer, and is refused rather than rounded.
    if abs(value_of(protocol, code, raw) - value) > 1e-9 * max(1.0, abs(value)):
        return Exc.ILLEGAL_VALUE, f"{text} is finer than {code}'s setting increment"
    return ParameterWrite(code, raw)


def _why(exc: Exc, request: WriteRequest, line: LineConfig, state: DriveState) -> str:
    """What a :class:`~._control.Controller` refusal means, for the error reply."""
    if exc is Exc.ILLEGAL_FUNCTION:
        if isinstance(request, ParameterWrite):
            return f"the configuration does not allow writing {request.code} to this drive"
        if not line.control_allowed(state.node):
            return "the configuration does not allow control of this drive"
        return "take the control lease first (publish to …/set/lease)"
    if exc is Exc.DEVICE_BUSY:
        return f"another client ({state.lease.holder}) holds the control lease"
    if exc is Exc.ILLEGAL_VALUE:
        if isinstance(request, SetFrequency):
            return f"{request.hz:g} Hz is outside 0 Hz .. the drive's maximum"
        return "the drive must not get this value (out of range or finer than its step)"
    if exc is Exc.DEVICE_FAILURE:
        return "the drive refused it (NAK), or read back something else"
    if exc is Exc.TARGET_FAILED:
        return "the drive did not answer"
    return exc.name.lower().replace("_", " ")


# -- the bridge -----------------------------------------------------------------------------------


async def _cancel_and_wait(tasks: set[asyncio.Task[None]]) -> None:
    """Cancel *tasks* and wait until each has ended, cancelling again any still running.

    Once is not always enough on Python 3.11: a task inside ``asyncio.wait_for``
    (aiomqtt's publish and subscribe) can lose a cancellation that arrives as
    the awaited result does (gh-86296), and run on.
    """
    pending = {task for task in tasks if not task.done()}
    while pending:
        for task in pending:
            task.cancel()
        _, pending = await asyncio.wait(pending, timeout=CANCEL_AGAIN_S)
    for task in tasks:
        if not task.cancelled():
            task.exception()  # retrieved: the caller has the connection's error already


class MqttBridge:
    """The gateway's MQTT client (see the module docstring)."""

    def __init__(
        self,
        config: MqttConfig,
        gateway_id: str,
        lines: Sequence[BridgedLine],
        stale_after_s: float,
    ) -> None:
        self.config = config
        self.topics = Topics(gateway_id, config.prefix)
        self.stale_after_s = stale_after_s
        self.stats = BridgeStats()
        self._lines = list(lines)
        self._drives = {
            (line.config.name, node): _Drive(line, state)
            for line in self._lines
            for node, state in line.states.items()
        }
        self._birth = f"{config.discovery_prefix}/status"
        #: Waiting to be published: the latest per topic (state, availability, discovery).
        self._pending: dict[str, _Out] = {}
        #: Error replies, in order (each is an answer: never coalesced).
        self._errors: collections.deque[_Out] = collections.deque()
        self._wake = asyncio.Event()
        #: The latest state message of each drive (republished on every connect).
        self._latest: dict[Key, _Out] = {}
        #: The availability last put in the outbox, per drive.
        self._availability: dict[Key, bool] = {}
        #: Loop time each tripped drive was first seen tripped.
        self._tripped_since: dict[Key, float] = {}
        self._client: aiomqtt.Client | None = None
        #: Changes on every connect and loss: a command of an older epoch is stale.
        self._epoch = 0
        self._commands: dict[Key, asyncio.Queue[tuple[int, str, bytes, str]]] = {}
        self._workers: dict[Key, asyncio.Task[None]] = {}
        self._busy: set[Key] = set()
        self._task: asyncio.Task[None] | None = None
        self._closing = False
        #: Loop time by which a closing connection stops flushing and says "offline".
        self._close_by = math.inf

    @property
    def connected(self) -> bool:
        return self._client is not None

    def start(self) -> None:
        """Connect (and keep reconnecting) in the background."""
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run(), name="mqtt bridge")

    # -- from the gateway ----------------------------------------------------------------

    def on_sample(self, state: DriveState, sample: Sample) -> None:
        """A poll of *state*'s drive ended (its state updated): publish it. Never blocks."""
        if self._closing:
            return
        key = (state.line, state.node)
        self.stats.samples[key] += 1
        if state.tripped:
            self._tripped_since.setdefault(key, sample.timestamp)
        elif state.tripped is False:
            self._tripped_since.pop(key, None)
        loop_now = asyncio.get_running_loop().time()
        # The poll ended at sample.timestamp, on the loop's clock: the same instant in Unix time.
        self._publish_state(key, state, loop_now, time.time() - (loop_now - sample.timestamp))
        available = _available(state)
        if self._availability.get(key) != available:
            self._availability[key] = available
            self._put(self._availability_out(key))

    def _publish_state(self, key: Key, state: DriveState, now: float, wall: float) -> None:
        message = state_message(
            self.topics.gateway,
            state,
            now=now,
            wall=wall,
            stale_after_s=self.stale_after_s,
            tripped_since=self._tripped_since.get(key),
        )
        out = _Out(self.topics.state(*key), message.to_json(), retain=True, drive=key)
        self._latest[key] = out
        self._put(out)

    def _availability_out(self, key: Key) -> _Out:
        payload = AVAILABLE if self._availability.get(key) else UNAVAILABLE
        return _Out(self.topics.drive_availability(*key), payload.encode(), retain=True)

    # -- the outbox ----------------------------------------------------------------------

    def _put(self, out: _Out) -> None:
        old = self._pending.pop(out.topic, None)
        if old is not None and old is not out and old.drive is not None:
            self.stats.replaced[old.drive] += 1
            _log.debug("%s: replaced by a newer state before it was sent", out.topic)
        self._pending[out.topic] = out
        self._wake.set()

    def _put_error(self, out: _Out) -> None:
        if len(self._errors) >= MAX_ERRORS:
            dropped = self._errors.popleft()
            self.stats.errors_dropped += 1
            _log.debug("error reply on %s dropped: %d waiting", dropped.topic, MAX_ERRORS)
        self._errors.append(out)
        self._wake.set()

    def _announce(self) -> None:
        """Everything retained, again: discovery, availability, the latest states."""
        if self.config.discovery:
            configs = [line.config for line in self._lines]
            for topic, body in discovery(self.config, self.topics, configs):
                payload = json.dumps(body, separators=(",", ":")).encode()
                self._put(_Out(topic, payload, retain=True))
        # Only the drives polled already: "offline" for a drive not polled yet
        # would be a guess (it follows its first poll).
        for key in self._availability:
            self._put(self._availability_out(key))
        for out in self._latest.values():
            self._put(out)

    async def _send(self, client: aiomqtt.Client) -> None:
        """Publish everything waiting; raise the connection's error after counting what it cost."""
        while self._pending or self._errors:
            batch = list(self._pending.values())
            self._pending.clear()
            batch += self._errors
            self._errors.clear()
            for start in range(0, len(batch), MAX_IN_FLIGHT):
                chunk = batch[start : start + MAX_IN_FLIGHT]
                try:
                    results = await self._publish(client, chunk)
                except asyncio.CancelledError:
                    # Stopped mid-batch: this chunk's fate is unknown (it may have
                    # reached the broker), the rest was never sent. Counted as lost,
                    # since none is confirmed; never silently.
                    self.stats.lost += len(batch) - start
                    _log.debug("MQTT: stopped with %d messages unconfirmed", len(batch) - start)
                    raise
                failure: BaseException | None = None
                for out, result in zip(chunk, results, strict=True):
                    if isinstance(result, BaseException):
                        failure = failure or result
                        self.stats.lost += 1
                        _log.debug("%s: not published: %s", out.topic, result)
                        continue
                    self.stats.published += 1
                    if out.drive is not None:
                        self.stats.states[out.drive] += 1
                if failure is not None:
                    self.stats.lost += len(batch) - start - len(chunk)
                    raise failure

    async def _publish(
        self, client: aiomqtt.Client, chunk: list[_Out]
    ) -> list[BaseException | None]:
        """Publish *chunk* at once; each message's error, or None."""
        qos = self.config.qos
        if len(chunk) == 1:  # the usual case on a real line, one poll at a time: no task
            out = chunk[0]
            try:
                await client.publish(out.topic, out.payload, qos=qos, retain=out.retain)
            except Exception as exc:  # as gather(return_exceptions=True) would have it
                return [exc]
            return [None]
        results = await asyncio.gather(
            *(client.publish(o.topic, o.payload, qos=qos, retain=o.retain) for o in chunk),
            return_exceptions=True,
        )
        return [r if isinstance(r, BaseException) else None for r in results]

    async def _publisher(self, client: aiomqtt.Client) -> None:
        task = asyncio.current_task()
        assert task is not None
        while True:
            await self._wake.wait()
            self._wake.clear()
            await self._send(client)
            if task.cancelling():
                # aiomqtt's publish awaits asyncio.wait_for, which on Python 3.11 returns
                # the result and drops a cancellation that arrives as the broker's
                # acknowledgement does (gh-86296). This task then waited on _wake for
                # good, and the gateway's stop with it (seen: the MQTT benchmark's
                # child, 2 runs in 7). The cancellation is not lost: raise it here.
                raise asyncio.CancelledError

    # -- the connection ------------------------------------------------------------------

    def _make_client(self) -> aiomqtt.Client:
        config = self.config
        tls = None
        if config.tls:
            tls = aiomqtt.TLSParameters(
                ca_certs=None if config.tls_ca is None else str(config.tls_ca)
            )
        client = aiomqtt.Client(
            config.host,
            config.port,
            identifier=config.client_id,
            username=config.username,
            password=config.password,
            tls_params=tls,
            will=aiomqtt.Will(self.topics.availability, UNAVAILABLE, config.qos, retain=True),
            clean_session=True,  # nothing the broker kept for us: no stale command
            keepalive=config.keepalive_s,
            # A broker that stops reading: paho's queue (QoS 0 publishes return at
            # once) is bounded too; past it, publish fails and the bridge reconnects.
            max_queued_outgoing_messages=MAX_QUEUED,
        )
        client.pending_calls_threshold = 2 * MAX_IN_FLIGHT
        return client

    async def _run(self) -> None:
        delay = BACKOFF_FIRST_S
        failing = False  # an outage already logged (its next failed attempts are DEBUG)
        while True:
            good = False
            try:
                async with self._make_client() as client:
                    try:
                        await self._setup(client)
                        good = True
                        if failing:
                            _log.info("MQTT: connected again to %s", self.config.url)
                        else:
                            _log.info("MQTT: connected to %s as %s",
                                      self.config.url, self.topics.gateway)  # fmt: skip
                        failing = False
                        await self._session(client)
                    except asyncio.CancelledError:
                        if self._closing:
                            await self._say_offline(client)
                        raise  # and the clean disconnect: the broker drops the will
            except aiomqtt.MqttError as exc:
                reason = str(exc) or type(exc).__name__
            except Exception as exc:  # a bug of ours must not end MQTT for good
                _log.exception("MQTT: unexpected error")
                reason = f"{type(exc).__name__}: {exc}"
            finally:
                self._client = None
                self._epoch += 1  # commands received on that connection are stale now
            if good:
                self.stats.losses += 1
                delay = BACKOFF_FIRST_S  # a good connection resets the back-off
                _log.warning("MQTT: lost %s (%s); reconnecting", self.config.url, reason)
                failing = True
            elif not failing:
                _log.warning("MQTT: cannot connect to %s (%s); retrying", self.config.url, reason)
                failing = True
            else:
                _log.debug("MQTT: %s still unreachable (%s)", self.config.url, reason)
            await asyncio.sleep(delay)
            delay = min(delay * 2, BACKOFF_MAX_S)

    async def _say_offline(self, client: aiomqtt.Client) -> None:
        """A clean stop: what is waiting, then "offline" (a clean disconnect has no will)."""
        loop = asyncio.get_running_loop()
        try:
            async with asyncio.timeout(max(0.1, self._close_by - loop.time())):
                await self._send(client)
                await client.publish(
                    self.topics.availability, UNAVAILABLE, qos=self.config.qos, retain=True
                )
        except (aiomqtt.MqttError, TimeoutError) as exc:
            # The disconnect that follows is clean, so the broker drops the will:
            # "online" stays until the gateway connects again. Said loudly.
            _log.warning("MQTT: could not say offline before stopping: %s", exc or "time-out")

    async def _setup(self, client: aiomqtt.Client) -> None:
        """Subscribe, say online, and queue everything retained again."""
        qos = self.config.qos
        await client.subscribe(self.topics.command_filter, qos=qos)
        if self.config.discovery:
            await client.subscribe(self._birth, qos=qos)
        await client.publish(self.topics.availability, AVAILABLE, qos=qos, retain=True)
        self.stats.connects += 1
        self._epoch += 1
        self._client = client
        self._announce()

    async def _session(self, client: aiomqtt.Client) -> None:
        """Publish and receive until the connection fails (raises its MqttError)."""
        tasks = {
            asyncio.create_task(self._publisher(client), name="mqtt publisher"),
            asyncio.create_task(self._receiver(client), name="mqtt receiver"),
        }
        try:
            done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            await _cancel_and_wait(tasks)
        for task in done:
            task.result()  # the connection's error
        raise aiomqtt.MqttError("the session ended")  # both loops run until an error

    async def _receiver(self, client: aiomqtt.Client) -> None:
        async for message in client.messages:
            topic = message.topic.value
            payload = message.payload if isinstance(message.payload, bytes) else b""
            if topic == self._birth:
                # Home Assistant (re)started: it needs the configs and states again. A
                # retained birth is the one it sent before we connected: already covered.
                if payload == AVAILABLE.encode() and not message.retain:
                    _log.info("MQTT: Home Assistant is online: republishing discovery")
                    self._announce()
                continue
            self._receive_command(topic, payload, retained=message.retain)

    # -- commands ------------------------------------------------------------------------

    def _receive_command(self, topic: str, payload: bytes, *, retained: bool) -> None:
        self.stats.commands += 1
        parsed = self.topics.parse_command(topic)
        drive = None if parsed is None else self._drives.get(parsed[:2])
        if parsed is None or drive is None:
            self.stats.ignored += 1
            _log.debug("MQTT: %s names no drive of this gateway: ignored", topic)
            return
        line, node, what = parsed
        if retained:
            # Stored by the broker, not sent now: carrying it out would replay it.
            self._refuse(
                drive,
                topic,
                what,
                payload,
                Exc.ILLEGAL_FUNCTION,
                "a retained command is never carried out (publish commands without retain)",
            )
            return
        queue = self._commands.get((line, node))
        if queue is None:
            queue = self._commands[line, node] = asyncio.Queue(MAX_COMMANDS)
            self._workers[line, node] = asyncio.create_task(
                self._worker((line, node), queue), name=f"mqtt commands {line} {node}"
            )
        try:
            queue.put_nowait((self._epoch, topic, payload, what))
        except asyncio.QueueFull:
            self._refuse(
                drive,
                topic,
                what,
                payload,
                Exc.DEVICE_BUSY,
                f"{MAX_COMMANDS} commands are already waiting for this drive",
            )

    async def _worker(self, key: Key, queue: asyncio.Queue[tuple[int, str, bytes, str]]) -> None:
        """Carry out one drive's commands, in order."""
        drive = self._drives[key]
        while not self._closing:
            epoch, topic, payload, what = await queue.get()
            if epoch != self._epoch:
                self.stats.discarded += 1
                _log.debug("MQTT: %s %r discarded: received before the connection was lost",
                           topic, payload)  # fmt: skip
                continue
            self._busy.add(key)
            try:
                await self._carry_out(drive, topic, what, payload)
            finally:
                self._busy.discard(key)

    async def _carry_out(self, drive: _Drive, topic: str, what: str, payload: bytes) -> None:
        state, line = drive.state, drive.line
        request = _request(state.protocol, what, payload)
        if isinstance(request, tuple):
            self._refuse(drive, topic, what, payload, *request)
            return
        refusal = await line.controller.write(CLIENT, state, request)  # audited there
        if refusal is not None:
            self._refuse(
                drive, topic, what, payload, refusal, _why(refusal, request, line.config, state),
                audited=True,
            )  # fmt: skip
            return
        if not isinstance(request, Heartbeat):
            # The write's read-back is in the cache already: show it now, not at the next poll.
            loop_now = asyncio.get_running_loop().time()
            self._publish_state((state.line, state.node), state, loop_now, time.time())

    def _refuse(
        self,
        drive: _Drive,
        topic: str,
        what: str,
        payload: bytes,
        exc: Exc,
        reason: str,
        *,
        audited: bool = False,
    ) -> None:
        self.stats.refused += 1
        text = payload.decode("utf-8", errors="replace")
        error = f"{exc.name}: {reason}"
        _log.debug("MQTT: %s %r refused: %s", topic, text, error)
        if not audited:  # the controller audits what it judges; this judged it before
            drive.line.controller.audit.record(
                CLIENT, drive.state, f"mqtt {what}", None, text, f"refused: {error}"
            )
        body = {"topic": topic, "payload": text, "error": error, "time": time.time()}
        self._put_error(
            _Out(
                self.topics.error(drive.state.line, drive.state.node),
                json.dumps(body).encode(),
                retain=False,
            )
        )

    # -- stopping ------------------------------------------------------------------------

    async def close(self) -> None:
        """Stop: finish the write under way, flush, say "offline", disconnect."""
        if self._task is None:
            return
        self._closing = True
        self._epoch += 1  # commands waiting are not carried out any more
        loop = asyncio.get_running_loop()
        # A write under way finishes (a write and its read-back stay together; its
        # worker then sees _closing and ends); the idle workers end now.
        busy = [task for key, task in self._workers.items() if key in self._busy]
        for key, task in self._workers.items():
            if key not in self._busy:
                task.cancel()
        if busy:
            await asyncio.wait(busy, timeout=CLOSE_TIMEOUT_S)
        await _cancel_and_wait(set(self._workers.values()))
        waiting = sum(queue.qsize() for queue in self._commands.values())
        if waiting:
            self.stats.discarded += waiting
            _log.debug("MQTT: %d commands discarded: the gateway is stopping", waiting)
        # The connection's own task says "offline" as it ends (see _run), after
        # anything it was publishing: never before an "online" still on its way.
        self._close_by = loop.time() + CLOSE_TIMEOUT_S
        await _cancel_and_wait({self._task})
        self._task = None
        pending = len(self._pending) + len(self._errors)
        if pending:
            self.stats.lost += pending
            _log.debug("MQTT: %d messages not published before stopping", pending)
