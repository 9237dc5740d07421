"""Home Assistant's MQTT discovery: the configs that make each drive a device with entities.

Sans-IO: :func:`discovery` yields ``(topic, payload)`` for every retained
config (``homeassistant/<component>/<node_id>/<object_id>/config``). The
gateway is a device of its own (a connectivity sensor); each drive is a
device naming the gateway as ``via_device``, with sensors for what its
profile measures, a status sensor (the state in words), a trip sensor when
its profile reads trip histories, an event entity (refused, tripped,
lapsed: :mod:`._drive_events`), another for its trip records when the
gateway keeps them (``…/trip``), a number per parameter its configuration
grants, and, for a drive whose configuration grants control, a number
(set frequency), a select (direction) and buttons (run forward, run
reverse, stop, the lease heartbeat).

Decisions:

- **Identity.** A drive's device is named ``<gateway id> <line> <noun>
  <node>`` (``gw1 hall-a node 1``) and its ids hold the gateway id too, so
  two gateways with a line of the same name are two devices, and which
  drive gets an ``_2`` never depends on discovery order (issue 43). A
  discovery node id holds only ``[A-Za-z0-9_-]`` and an entity id only
  ``[a-z0-9_]``: the configuration refuses two line names written alike
  there (``a.b`` and ``a_b``, ``Hall`` and ``hall``).
- **Entity ids as documented on every Home Assistant from 2024 on**: each
  config sends ``default_entity_id`` (``sensor.sj300_gw1_hall_3_power``,
  honoured from 2025.10) and ``object_id`` (the part after the dot, which
  older releases build the id from; deprecated in 2025.10, ignored from
  2026.4, and harmless there).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterator, Mapping, Sequence
from typing import Any, Final

from ... import __version__
from ...profiles import ParameterSpec, get_profile
from .. import GatewayDrive, GatewayView, LineConfig, ServedDrive
from ._config import MqttConfig
from ._drive_events import EVENT_TYPES, TRIP_EVENT_TYPES
from ._topics import AVAILABLE, UNAVAILABLE, Topics

__all__ = [
    "FrequencyLimits",
    "discovery",
    "drive_discovery",
    "iter_discovery",
    "node_id",
    "served_discovery",
]

_NOT_IN_NODE_ID: Final = re.compile(r"[^A-Za-z0-9_-]")
_NOT_IN_ENTITY_ID: Final = re.compile(r"[^a-z0-9_]")


def node_id(*parts: object) -> str:
    """A Home Assistant discovery node id: ``[A-Za-z0-9_-]`` only."""
    return _NOT_IN_NODE_ID.sub("_", "_".join(map(str, parts)))


#: The sensors of every drive: object id, name, state key, unit, device class.
_SENSORS: Final = (
    ("output_frequency", "Output frequency", "output_frequency_hz", "Hz", "frequency"),
    ("output_current", "Output current", "output_current_a", "A", "current"),
    ("output_voltage", "Output voltage", "output_voltage_v", "V", "voltage"),
)
#: The sensors of the optional values, for the drives whose profile measures them
#: (``Capabilities.measures`` names the state key).
_OPTIONAL_SENSORS: Final = (
    ("power", "Power", "power_kw", "kW", "power"),
    ("output_torque", "Output torque", "output_torque_percent", "%", None),
)
# Home Assistant's MQTT sensor takes the text "None" as "unknown": a stale
# value (null) shows as unknown, not as 0 or as an error.
_STATUS_TEMPLATE: Final = (
    "{% if value_json.state is none %}None{% else %}{{ value_json.state }}{% endif %}"
)
#: The option a state the profile does not list shows as (its status fields say more).
OTHER_STATE: Final = "other"
#: The direction select's options: the state message's ``direction`` words.
_DIRECTIONS: Final = ("stop", "forward", "reverse")
_DIRECTION_TEMPLATE: Final = (
    "{% if value_json.direction is none %}None{% else %}{{ value_json.direction }}{% endif %}"
)
# The option chosen, as the command topic takes it (COMMAND_DIRECTIONS).
_DIRECTION_COMMAND: Final = "{{ 'stop' if value == 'stop' else 'run_' ~ value }}"
_TRIP_TEMPLATE: Final = (
    "{% if value_json.tripped is none %}None"
    "{% elif value_json.tripped %}{{ value_json.trip or 'tripped' }}"
    "{% else %}ok{% endif %}"
)
#: The trip sensor's attribute: what the present trip means (null when none is known).
_TRIP_ATTRIBUTES: Final = "{{ {'meaning': value_json.trip_meaning} | tojson }}"
_BUTTONS: Final = (
    ("run_forward", "Run forward", "command", "run_forward"),
    ("run_reverse", "Run reverse", "command", "run_reverse"),
    ("stop", "Stop", "command", "stop"),
    ("lease", "Control lease heartbeat", "lease", "renew"),
)


def discovery(
    config: MqttConfig,
    topics: Topics,
    lines: Sequence[LineConfig],
    *,
    limits: Mapping[tuple[str, int], float] | None = None,
    trips: bool = False,
) -> Iterator[tuple[str, dict[str, Any]]]:
    """Every Home Assistant discovery config: ``(topic, payload)``; *trips*: the
    gateway keeps trip records (each drive has an event entity for them).

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
            **_ids("binary_sensor", f"{gateway_device}_connectivity"),
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
    known = {} if limits is None else limits
    for line in lines:
        for node in line.nodes:
            yield from drive_discovery(
                config, topics, line, node, known.get((line.name, node)), trips=trips
            )


def drive_discovery(
    config: MqttConfig,
    topics: Topics,
    line: LineConfig,
    node: int,
    max_hz: float | None = None,
    *,
    trips: bool = False,
) -> Iterator[tuple[str, dict[str, Any]]]:
    """One drive's discovery configs (:func:`discovery`); *max_hz*: the set frequency's
    maximum, the drive's own once known (else the protocol's highest)."""
    prefix, gateway = config.discovery_prefix, topics.gateway
    origin = {"name": "sj300-async", "sw_version": __version__}
    gateway_device = node_id("sj300", gateway)
    profile = get_profile(line.protocol)
    model, manufacturer, noun = profile.model, profile.manufacturer, profile.node_noun
    measures = profile.capabilities.measures
    sensors = _SENSORS + tuple(s for s in _OPTIONAL_SENSORS if s[2] in measures)
    drive = node_id("sj300", gateway, line.name, node)
    state_topic = topics.state(line.name, node)
    common: dict[str, Any] = {
        "device": {
            "identifiers": [drive],
            "name": f"{gateway} {line.name} {noun} {node}",
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
        json_attributes_topic=state_topic,
        json_attributes_template="{{ (value_json.status or {}) | tojson }}",
        **_status_keys(profile.capabilities.states),
    )
    if profile.capabilities.trip_history:  # a trip is named only from the history
        yield entity(
            "sensor",
            "trip",
            "Trip",
            state_topic=state_topic,
            json_attributes_topic=state_topic,
            json_attributes_template=_TRIP_ATTRIBUTES,
            **_trip_keys([trip.code for trip in profile.trip_codes()]),
        )
    yield entity(
        "event",
        "events",
        "Events",
        state_topic=topics.event(line.name, node),
        event_types=list(EVENT_TYPES),
    )
    if trips:
        yield entity(
            "event",
            "trips",
            "Trip records",
            state_topic=topics.trip(line.name, node),
            event_types=list(TRIP_EVENT_TYPES),
        )
    for code in sorted(line.writable_parameters(node)):
        spec = profile.parameters.spec(code)
        yield entity(
            "number",
            node_id("parameter", code),  # Pr.7: parameter_Pr_7
            f"{code} {spec.name}",
            **_parameter_keys(
                spec,
                topics.command(line.name, node, code),
                state_topic if code in line.parameters else None,
            ),
        )
    if not line.control_allowed(node):
        return
    yield entity(
        "number",
        "set_frequency",
        "Set frequency",
        command_topic=topics.command(line.name, node, "frequency_hz"),
        state_topic=state_topic,
        value_template="{{ value_json.set_frequency_hz }}",
        min=0,
        max=profile.max_frequency_hz if max_hz is None else max_hz,
        step=0.01,
        mode="box",
        unit_of_measurement="Hz",
        device_class="frequency",
        retain=False,
    )
    yield entity(
        "select",
        "direction",
        "Direction",
        command_topic=topics.command(line.name, node, "command"),
        command_template=_DIRECTION_COMMAND,
        state_topic=state_topic,
        value_template=_DIRECTION_TEMPLATE,
        options=list(_DIRECTIONS),
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


class FrequencyLimits:
    """The set-frequency numbers' maximum: each drive's own once known (issue 43).

    Home Assistant's number offered up to 400 Hz on a drive whose maximum
    (A004, polled) is 50 Hz. The bridge asks :meth:`changed` at every
    snapshot: a drive's served maximum that differs from the one its config
    was last published with means publishing that config again (once at the
    first read of the parameter, then at a write of it).
    """

    def __init__(self) -> None:
        #: Per drive: the maximum its set-frequency config was last published with.
        self.known: dict[tuple[str, int], float] = {}

    def changed(self, served: ServedDrive) -> bool:
        """True (and remembered) when *served*'s maximum is not the one last published."""
        snapshot = served.snapshot
        key, limit = (snapshot.line, snapshot.node), served.max_frequency_hz()
        # Not published with one of its own yet: with the protocol's highest.
        if self.known.get(key, served.highest_frequency_hz) == limit:
            return False
        self.known[key] = limit
        return True

    def config(
        self, config: MqttConfig, topics: Topics, drive: GatewayDrive | None
    ) -> list[tuple[str, dict[str, Any]]]:
        """*drive*'s set-frequency config with its maximum now (none without control)."""
        if drive is None:
            return []
        found = drive_discovery(config, topics, drive.line, drive.node, self.known.get(drive.key))
        return [c for c in found if c[0].endswith("/set_frequency/config")]


def iter_discovery(
    config: MqttConfig,
    topics: Topics,
    gateway: GatewayView | None,
    limits: Mapping[tuple[str, int], float] | None = None,
) -> Iterator[tuple[str, dict[str, Any]]]:
    """Every config of the drives *gateway* serves, each made as it is asked for (none
    with ``discovery`` off)."""
    if not config.discovery or gateway is None:
        return
    lines = list(dict.fromkeys(drive.line for drive in gateway.drives))
    trips = gateway.trip_records is not None
    yield from discovery(config, topics, lines, limits=limits, trips=trips)


def served_discovery(
    config: MqttConfig,
    topics: Topics,
    gateway: GatewayView | None,
    limits: Mapping[tuple[str, int], float] | None = None,
) -> list[tuple[str, dict[str, Any]]]:
    """Every config of the drives *gateway* serves now (none with ``discovery`` off)."""
    return list(iter_discovery(config, topics, gateway, limits))


def _status_keys(states: Sequence[str]) -> dict[str, Any]:
    """The status sensor's value: an enum of the profile's *states* (and
    :data:`OTHER_STATE` for a word it does not list), or plain text without them."""
    if not states:
        return {"value_template": _STATUS_TEMPLATE}
    listed = ", ".join(f"'{state}'" for state in states)
    return {
        "value_template": (
            "{% set s = value_json.state %}{% if s is none %}None"
            f"{{% elif s in [{listed}] %}}{{{{ s }}}}{{% else %}}{OTHER_STATE}{{% endif %}}"
        ),
        "device_class": "enum",
        "options": [*states, OTHER_STATE],
    }


def _trip_keys(codes: Sequence[str]) -> dict[str, Any]:
    """The trip sensor's value: ``ok``, ``tripped`` (before the history names it) or the
    code, as an enum of the profile's *codes* (:data:`OTHER_STATE` for one it does not
    name), or plain text without them."""
    if not codes:
        return {"value_template": _TRIP_TEMPLATE}
    listed = ", ".join(f"'{code}'" for code in codes)
    return {
        "value_template": (
            "{% if value_json.tripped is none %}None"
            "{% elif not value_json.tripped %}ok"
            "{% elif value_json.trip is none %}tripped"
            f"{{% elif value_json.trip in [{listed}] %}}{{{{ value_json.trip }}}}"
            f"{{% else %}}{OTHER_STATE}{{% endif %}}"
        ),
        "device_class": "enum",
        "options": ["ok", "tripped", *codes, OTHER_STATE],
    }


def _parameter_keys(spec: ParameterSpec, command: str, state: str | None) -> dict[str, Any]:
    """A granted parameter's number: its range and step from the catalogue (the drive
    refuses a value between steps it does not take: ``invalid_value`` on ``…/error``),
    its value from the state message when the line polls it (else none is shown)."""
    keys: dict[str, Any] = {
        "command_topic": command,
        "min": spec.minimum,
        "max": spec.maximum,
        "step": 1 / spec.scale,
        "mode": "box",
        "entity_category": "config",
        "retain": False,
    }
    if spec.unit:
        keys["unit_of_measurement"] = spec.unit
    if state is not None:
        value = f"value_json.parameters[{spec.code!r}]"
        keys["state_topic"] = state
        keys["value_template"] = (
            f"{{% if {value} is defined and {value} is not none %}}{{{{ {value} }}}}"
            "{% else %}None{% endif %}"
        )
    return keys


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
    body = {
        "name": name,
        **_ids(component, f"{drive}_{object_id}"),
        **common,
        **keys,
    }
    return f"{prefix}/{component}/{drive}/{object_id}/config", body


def _ids(component: str, unique_id: str) -> dict[str, str]:
    """An entity's ids: its unique id, and the entity id it gets on every Home Assistant
    (``sensor.sj300_gw1_hall_a_3_power``: only ``[a-z0-9_]``), both ways of saying it."""
    object_id = _NOT_IN_ENTITY_ID.sub("_", unique_id.lower())
    return {
        "unique_id": unique_id,
        "object_id": object_id,
        "default_entity_id": f"{component}.{object_id}",
    }
