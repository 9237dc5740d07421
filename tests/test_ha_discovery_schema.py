"""The Home Assistant discovery checker accepts good payloads and can fail."""

from __future__ import annotations

import pytest
from ha_discovery_schema import check

DEVICE = {
    "identifiers": ["sj300_drive1"],
    "name": "Drive 1",
    "manufacturer": "Hitachi",
    "model": "SJ300",
    "sw_version": "1.0",
    "via_device": "sj300_gateway",
}
ORIGIN = {"name": "sj300_async", "sw_version": "0.1", "support_url": "https://example.org"}
AVAILABILITY = [
    {"topic": "sj300/bridge/status"},
    {"topic": "sj300/drive1/status", "payload_available": "up", "payload_not_available": "down"},
]
COMMON = {"device": DEVICE, "origin": ORIGIN, "availability": AVAILABILITY}

VALID: dict[str, dict[str, object]] = {
    "sensor": {
        **COMMON,
        "name": "Output frequency",
        "unique_id": "drive1_freq",
        "default_entity_id": "sensor.drive1_freq",
        "state_topic": "sj300/drive1/freq",
        "device_class": "frequency",
        "state_class": "measurement",
        "unit_of_measurement": "Hz",
        "suggested_display_precision": 2,
        "availability_mode": "all",
        "entity_category": "diagnostic",
        "expire_after": 60,
    },
    "binary_sensor": {
        **COMMON,
        "name": "Running",
        "unique_id": "drive1_running",
        "object_id": "drive1_running",
        "state_topic": "sj300/drive1/running",
        "device_class": "running",
        "payload_on": "1",
        "payload_off": "0",
    },
    "number": {
        **COMMON,
        "name": "Frequency setpoint",
        "unique_id": "drive1_setpoint",
        "command_topic": "sj300/drive1/setpoint/set",
        "state_topic": "sj300/drive1/setpoint",
        "device_class": "frequency",
        "unit_of_measurement": "Hz",
        "min": 0,
        "max": 400.0,
        "step": 0.01,
        "mode": "box",
        "entity_category": "config",
        "qos": 1,
        "retain": False,
    },
    "button": {
        **COMMON,
        "name": "Reset trip",
        "unique_id": "drive1_reset",
        "command_topic": "sj300/drive1/reset",
        "payload_press": "RESET",
        "device_class": "restart",
    },
    "select": {
        **COMMON,
        "name": "Direction",
        "unique_id": "drive1_direction",
        "command_topic": "sj300/drive1/direction/set",
        "state_topic": "sj300/drive1/direction",
        "options": ["forward", "reverse", "stop"],
    },
    "event": {
        **COMMON,
        "name": "Trip",
        "unique_id": "drive1_trip",
        "state_topic": "sj300/drive1/trip",
        "event_types": ["overcurrent", "overvoltage"],
    },
}
ENUM_SENSOR: dict[str, object] = {
    "name": "Status",
    "unique_id": "drive1_status",
    "state_topic": "sj300/drive1/status_code",
    "device_class": "enum",
    "options": ["stopped", "running", "tripped"],
}


def with_(component: str, **changes: object) -> dict[str, object]:
    return {**VALID[component], **changes}


def without(component: str, key: str) -> dict[str, object]:
    return {k: v for k, v in VALID[component].items() if k != key}


def one_problem(component: str, payload: dict[str, object], *words: str) -> None:
    problems = check(component, payload)
    assert len(problems) == 1, problems
    for word in words:
        assert word in problems[0], problems


@pytest.mark.parametrize("component", sorted(VALID))
def test_valid_payloads_pass(component: str) -> None:
    assert check(component, VALID[component]) == []


def test_enum_sensor_with_options_passes() -> None:
    assert check("sensor", ENUM_SENSOR) == []


def test_unknown_key_is_reported() -> None:
    one_problem("sensor", with_("sensor", stat_t="x"), "unknown key", "'stat_t'")
    one_problem("button", with_("button", state_topic="x"), "unknown key", "'state_topic'")


def test_unknown_key_in_device_and_origin_is_reported() -> None:
    device = {**DEVICE, "colour": "blue"}
    one_problem("event", with_("event", device=device), "device", "'colour'")
    one_problem("event", with_("event", origin={**ORIGIN, "url": "x"}), "origin", "'url'")


@pytest.mark.parametrize(
    ("component", "key"),
    [
        ("sensor", "state_topic"),
        ("binary_sensor", "state_topic"),
        ("number", "command_topic"),
        ("button", "command_topic"),
        ("select", "command_topic"),
        ("select", "options"),
        ("event", "event_types"),
        ("event", "state_topic"),
    ],
)
def test_missing_required_key_is_reported(component: str, key: str) -> None:
    one_problem(component, without(component, key), "missing required key", repr(key))


def test_origin_needs_a_name_and_device_an_identifier() -> None:
    one_problem("sensor", with_("sensor", origin={"sw_version": "1"}), "origin", "'name'")
    device = {"name": "Drive 1"}
    one_problem("sensor", with_("sensor", device=device), "'identifiers'")


@pytest.mark.parametrize(
    ("component", "key", "value"),
    [
        ("sensor", "state_topic", 5),
        ("sensor", "suggested_display_precision", "2"),
        ("sensor", "expire_after", -1),
        ("binary_sensor", "off_delay", 1.5),
        ("number", "min", "0"),
        ("number", "retain", "false"),
        ("number", "qos", 3),
        ("select", "options", "forward"),
        ("select", "options", ["forward", 1]),
        ("event", "event_types", "overcurrent"),
        ("button", "command_topic", "sj300/+/reset"),
        ("button", "enabled_by_default", 1),
        ("sensor", "device", ["sj300_drive1"]),
        ("sensor", "availability", {"topic": "x"}),
    ],
)
def test_wrong_type_is_reported(component: str, key: str, value: object) -> None:
    one_problem(component, with_(component, **{key: value}), repr(key))


def test_wrong_type_inside_device_and_availability_is_reported() -> None:
    device = {**DEVICE, "identifiers": "sj300_drive1"}
    one_problem("sensor", with_("sensor", device=device), "device", "'identifiers'")
    availability = [{"topic": "x", "payload_available": 1}]
    one_problem("sensor", with_("sensor", availability=availability), "'payload_available'")
    one_problem("sensor", with_("sensor", availability=[{"payload_available": "1"}]), "'topic'")


@pytest.mark.parametrize(
    ("component", "key", "value"),
    [
        ("sensor", "device_class", "rpm"),
        ("binary_sensor", "device_class", "frequency"),
        ("number", "device_class", "enum"),
        ("button", "device_class", "press"),
        ("event", "device_class", "trip"),
        ("sensor", "state_class", "total_decreasing"),
        ("number", "entity_category", "system"),
        ("number", "mode", "dial"),
        ("select", "availability_mode", "some"),
    ],
)
def test_invalid_enum_value_is_reported(component: str, key: str, value: object) -> None:
    one_problem(component, with_(component, **{key: value}), repr(key))


def test_enum_sensor_without_options_is_reported() -> None:
    payload = {k: v for k, v in ENUM_SENSOR.items() if k != "options"}
    one_problem("sensor", payload, "enum", "'options'")


def test_enum_sensor_with_unit_or_state_class_is_reported() -> None:
    one_problem("sensor", {**ENUM_SENSOR, "unit_of_measurement": "Hz"}, "'unit_of_measurement'")
    one_problem("sensor", {**ENUM_SENSOR, "state_class": "measurement"}, "'state_class'")


def test_sensor_options_need_device_class_enum() -> None:
    payload = {**ENUM_SENSOR, "device_class": "frequency"}
    one_problem("sensor", payload, "'options'", "enum")
    one_problem("sensor", {**ENUM_SENSOR, "options": []}, "'options'")


def test_number_range_and_availability_exclusivity() -> None:
    one_problem("number", with_("number", min=10, max=5), "'max'", "'min'")
    both = with_("sensor", availability_topic="sj300/bridge/status")
    one_problem("sensor", both, "'availability_topic'")


def test_every_problem_is_reported_not_just_the_first() -> None:
    payload = {**without("number", "command_topic"), "bogus": 1, "mode": "dial"}
    assert len(check("number", payload)) == 3
    assert check("light", {}) == ["unsupported component 'light'"]
