"""A small, dependency-free checker of Home Assistant MQTT discovery payloads.

Rules read (not copied) from Home Assistant core's own source, the 2025.x line
(stored copies of the ``dev`` branch from 2025; the copies carry no release
tag, so no single tag is pinned), files:

* ``homeassistant/components/mqtt/{sensor,binary_sensor,number,button,select,event}.py``:
  each ``_PLATFORM_SCHEMA_BASE`` / ``PLATFORM_SCHEMA_MODERN`` / ``DISCOVERY_SCHEMA``,
  sensor's ``validate_sensor_state_and_device_class_config``, number's ``validate_config``;
* ``mqtt/config.py`` (``MQTT_BASE_SCHEMA``, ``MQTT_RO_SCHEMA``, ``MQTT_RW_SCHEMA``),
  ``mqtt/schemas.py`` (availability, device, origin, ``MQTT_ENTITY_COMMON_SCHEMA``),
  ``mqtt/const.py`` (``AVAILABILITY_MODES``, ``CONF_DEFAULT_ENTITY_ID``), ``mqtt/util.py``;
* the device-class enums of ``sensor/const.py``, ``binary_sensor/__init__.py``,
  ``number/const.py`` (and ``NumberMode``), ``button/__init__.py``, ``event/__init__.py``.

Unknown keys: each platform's ``DISCOVERY_SCHEMA`` is its schema extended with
``extra=vol.REMOVE_EXTRA``, so HA silently *drops* an unknown top-level key (and one
in an availability item, a plain nested dict). ``device`` and ``origin`` are separate
``vol.Schema`` objects with the default ``PREVENT_EXTRA``: an unknown key there makes
HA *reject* the payload. Either way we report it.

Deliberately not checked: abbreviations (``stat_t``, ``dev``...) and the ``~`` topic
base, which HA expands first (we emit full keys, so they show up as unknown);
templates are not parsed; URLs are only checked to be strings; units are not checked
against ``DEVICE_CLASS_UNITS``; device-based discovery (``components``) is not
handled, though ``platform`` is accepted when it names the component, as in one of
its entries. HA's validators coerce (``cv.string`` takes numbers, ``cv.boolean``
takes ``"on"``); we are stricter and want the JSON type itself right.

Ours, not HA's schema: an ``enum`` sensor must list ``options`` (HA's MQTT schema
only demands the converse).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

Check = Callable[[object], str | None]  # None if fine, else what was expected


def _is(what: str, *types: type) -> Check:
    """Exactly these JSON types: a bool is neither an int nor a number here."""

    def check(v: object) -> str | None:
        return None if type(v) in types else what

    return check


_string = _is("a string", str)
_opt_string = _is("a string or null", str, type(None))
_boolean = _is("a boolean", bool)
_number = _is("a number", int, float)


def _positive_int(v: object) -> str | None:
    return None if type(v) is int and v >= 0 else "an integer >= 0"


def _qos(v: object) -> str | None:
    return None if type(v) is int and v in (0, 1, 2) else "0, 1 or 2"


def _str_list(v: object) -> str | None:
    ok = isinstance(v, list) and all(isinstance(x, str) for x in v)
    return None if ok else "a list of strings"


def _subscribe_topic(v: object) -> str | None:
    if not isinstance(v, str) or not v or "\0" in v:
        return "a non-empty topic string"
    levels = v.split("/")
    if any("+" in lv and lv != "+" for lv in levels) or (
        "#" in v and (levels[-1] != "#" or v.count("#") > 1)
    ):
        return "a valid topic filter"
    return None


def _publish_topic(v: object) -> str | None:
    if not isinstance(v, str) or not v or "\0" in v:
        return "a non-empty topic string"
    return "a topic without wildcards" if "+" in v or "#" in v else None


def _one_of(values: frozenset[str], nullable: bool = False) -> Check:
    def check(v: object) -> str | None:
        if (nullable and v is None) or (isinstance(v, str) and v.lower() in values):
            return None
        return "one of " + ", ".join(sorted(values))

    return check


def _words(text: str) -> frozenset[str]:
    return frozenset(text.split())


# NumberDeviceClass; SensorDeviceClass is these plus the four added below. absolute_humidity
# is a 2025 addition not in every 2025.x copy read; the other values were in all of them.
_NUMBER_CLASSES = _words(
    "absolute_humidity apparent_power aqi area atmospheric_pressure battery"
    " blood_glucose_concentration carbon_monoxide carbon_dioxide conductivity current"
    " data_rate data_size distance duration energy energy_distance energy_storage"
    " frequency gas humidity illuminance irradiance moisture monetary nitrogen_dioxide"
    " nitrogen_monoxide nitrous_oxide ozone ph pm1 pm10 pm25 power_factor power"
    " precipitation precipitation_intensity pressure reactive_power"
    " signal_strength sound_pressure speed sulphur_dioxide temperature"
    " volatile_organic_compounds volatile_organic_compounds_parts voltage volume"
    " volume_storage volume_flow_rate water weight wind_direction wind_speed"
)
DEVICE_CLASSES: dict[str, frozenset[str]] = {
    "sensor": _NUMBER_CLASSES | {"date", "enum", "timestamp", "reactive_energy"},
    "number": _NUMBER_CLASSES,
    "binary_sensor": _words(
        "battery battery_charging carbon_monoxide cold connectivity door garage_door gas"
        " heat light lock moisture motion moving occupancy opening plug power presence"
        " problem running safety smoke sound tamper update vibration window"
    ),
    "button": frozenset({"identify", "restart", "update"}),
    "event": frozenset({"doorbell", "button", "motion"}),
}
STATE_CLASSES = frozenset({"measurement", "measurement_angle", "total", "total_increasing"})

_BASE: dict[str, Check] = {"qos": _qos, "encoding": _string, "group": _str_list}
_COMMON: dict[str, Check] = {
    **_BASE,
    # availability (single form; the list form is checked by _availability)
    "availability_topic": _subscribe_topic,
    "availability_template": _string,
    "availability_mode": _one_of(frozenset({"all", "any", "latest"})),
    "payload_available": _string,
    "payload_not_available": _string,
    # MQTT_ENTITY_COMMON_SCHEMA
    "enabled_by_default": _boolean,
    "entity_category": _one_of(frozenset({"config", "diagnostic"})),
    "entity_picture": _string,
    "icon": _string,
    "json_attributes_topic": _subscribe_topic,
    "json_attributes_template": _string,
    "object_id": _string,  # deprecated in 2025.10 in favour of default_entity_id
    "default_entity_id": _string,
    "unique_id": _string,
    "name": _opt_string,
    "platform": _string,
}
_RO: dict[str, Check] = {"state_topic": _subscribe_topic, "value_template": _string}
_RW: dict[str, Check] = {
    "command_topic": _publish_topic,
    "optimistic": _boolean,
    "retain": _boolean,
    "state_topic": _subscribe_topic,
}

PLATFORM_KEYS: dict[str, dict[str, Check]] = {
    "sensor": {
        **_RO,
        "device_class": _one_of(DEVICE_CLASSES["sensor"], nullable=True),
        "expire_after": _positive_int,
        "force_update": _boolean,
        "last_reset_value_template": _string,
        "options": _str_list,
        "suggested_display_precision": _positive_int,
        "state_class": _one_of(STATE_CLASSES, nullable=True),
        "unit_of_measurement": _opt_string,
    },
    "binary_sensor": {
        **_RO,
        "device_class": _one_of(DEVICE_CLASSES["binary_sensor"], nullable=True),
        "expire_after": _positive_int,
        "force_update": _boolean,
        "off_delay": _positive_int,
        "payload_off": _string,
        "payload_on": _string,
    },
    "number": {
        **_RW,
        "command_template": _string,
        "device_class": _one_of(DEVICE_CLASSES["number"], nullable=True),
        "max": _number,
        "min": _number,
        "mode": _one_of(frozenset({"auto", "box", "slider"})),
        "payload_reset": _string,
        "step": _number,
        "unit_of_measurement": _opt_string,
        "value_template": _string,
    },
    "button": {
        "command_template": _string,
        "command_topic": _publish_topic,
        "device_class": _one_of(DEVICE_CLASSES["button"], nullable=True),
        "payload_press": _string,
        "retain": _boolean,
    },
    "select": {
        **_RW,
        "command_template": _string,
        "options": _str_list,
        "value_template": _string,
    },
    "event": {
        **_RO,
        "device_class": _one_of(DEVICE_CLASSES["event"]),
        "event_types": _str_list,
    },
}
REQUIRED: dict[str, tuple[str, ...]] = {
    "sensor": ("state_topic",),
    "binary_sensor": ("state_topic",),
    "number": ("command_topic",),
    "button": ("command_topic",),
    "select": ("command_topic", "options"),
    "event": ("state_topic", "event_types"),
}

_DEVICE_KEYS: dict[str, Check] = {
    "identifiers": _str_list,
    "connections": lambda v: (
        None
        if isinstance(v, list)
        and all(isinstance(c, list) and len(c) == 2 and not _str_list(c) for c in v)
        else "a list of [type, value] string pairs"
    ),
    **dict.fromkeys(
        _words(
            "manufacturer model model_id name hw_version serial_number sw_version via_device"
            " suggested_area configuration_url"
        ),
        _string,
    ),
}
_ORIGIN_KEYS: dict[str, Check] = dict.fromkeys(("name", "sw_version", "support_url"), _string)
_AVAILABILITY_ITEM_KEYS: dict[str, Check] = {
    "topic": _subscribe_topic,
    "payload_available": _string,
    "payload_not_available": _string,
    "value_template": _string,
}


def _check_keys(
    where: str, data: Mapping[str, object], keys: Mapping[str, Check], required: tuple[str, ...]
) -> list[str]:
    problems = [f"{where}missing required key {k!r}" for k in required if k not in data]
    for key, value in data.items():
        check = keys.get(key)
        if check is None:
            problems.append(f"{where}unknown key {key!r}")
        elif (expected := check(value)) is not None:
            problems.append(f"{where}{key!r} must be {expected}, got {value!r}")
    return problems


def _nested(
    where: str, value: object, keys: Mapping[str, Check], required: tuple[str, ...]
) -> list[str]:
    if not isinstance(value, dict):
        return [f"{where!r} must be a dict, got {value!r}"]
    return _check_keys(f"{where}: ", value, keys, required)


def _availability(value: object) -> list[str]:
    if not isinstance(value, list) or not value:
        return [f"'availability' must be a non-empty list of dicts, got {value!r}"]
    problems: list[str] = []
    for i, item in enumerate(value):
        problems += _nested(f"availability[{i}]", item, _AVAILABILITY_ITEM_KEYS, ("topic",))
    return problems


def _sensor_rules(p: Mapping[str, object]) -> list[str]:
    problems: list[str] = []
    device_class, options = p.get("device_class"), p.get("options")
    if "last_reset_value_template" in p and p.get("state_class") != "total":
        problems.append("'last_reset_value_template' needs state_class 'total'")
    if options is not None:
        if options == []:
            problems.append("'options' must not be empty")
        if device_class != "enum":
            problems.append("'options' is only allowed with device_class 'enum'")
    if device_class == "enum" or options is not None:
        problems += [
            f"{k!r} is not allowed on an enum sensor (device_class 'enum' / options)"
            for k in ("state_class", "unit_of_measurement")
            if p.get(k)
        ]
    if device_class == "enum" and options is None:
        problems.append("a sensor with device_class 'enum' needs 'options'")
    return problems


def check(component: str, payload: Mapping[str, object]) -> list[str]:
    """Return every problem found in a discovery payload; an empty list means valid."""
    if component not in PLATFORM_KEYS:
        return [f"unsupported component {component!r}"]
    keys = {**_COMMON, **PLATFORM_KEYS[component]}
    nested = {"device", "origin", "availability"}
    flat = {k: v for k, v in payload.items() if k not in nested}
    problems = _check_keys("", flat, keys, REQUIRED[component])
    if "device" in payload:
        device = payload["device"]
        problems += _nested("device", device, _DEVICE_KEYS, ())
        if isinstance(device, dict) and not (
            device.get("identifiers") or device.get("connections")
        ):
            problems.append("'device' needs at least one of 'identifiers' or 'connections'")
    if "origin" in payload:
        problems += _nested("origin", payload["origin"], _ORIGIN_KEYS, ("name",))
    if "availability" in payload:
        problems += _availability(payload["availability"])
        if "availability_topic" in payload:
            problems.append("'availability' and 'availability_topic' are mutually exclusive")
    if payload.get("platform", component) != component:
        problems.append(f"'platform' must be {component!r}")
    if component == "sensor":
        problems += _sensor_rules(payload)
    if component == "number":
        lo, hi, step = payload.get("min", 0.0), payload.get("max", 100.0), payload.get("step", 1.0)
        if isinstance(lo, int | float) and isinstance(hi, int | float) and lo >= hi:
            problems.append("'max' must be greater than 'min'")
        if isinstance(step, int | float) and step < 1e-3:
            problems.append("'step' must be >= 0.001")
    return problems
