"""A device's values in a sample, sans-IO: Device.values against each metric's own reader.

Device.values reads the served values' fields in one call and starts from
its constants (it runs at every sample); whatever the drive as served, it
must say what reading each metric one by one says, the latest refusal in
its two metrics. A constant metric's value is the device's own: its metrics
are shared by every device built alike (issue 44), so their readers do not
carry it.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from sj300_async.gateway import GatewayDrive, Lease, LineConfig, ServedValues, WriteGrant
from sj300_async.gateway.sparkplug import (
    LAST_REFUSAL,
    Device,
    DeviceFlags,
    decode_payload,
    encode_payload,
)
from sj300_async.profiles import ParameterReading, Trip, get_profile

LINES = {
    "read-only": LineConfig("l", "sim://", "sj300", (1,), parameters=("A004",)),
    "control": LineConfig(
        "l",
        "sim://",
        "sj300",
        (1,),
        parameters=("A004",),
        grants=(WriteGrant(frozenset({1}), frozenset({"F002"}), control=True),),
    ),
    "fr700": LineConfig("l", "sim://", "fr700", (1,)),
}
MAYBE_FLOAT = st.none() | st.floats(allow_nan=False)
MAYBE_BOOL = st.none() | st.booleans()
MAYBE_TEXT = st.none() | st.text(max_size=8)
TRIPS = st.none() | st.builds(
    Trip, code=st.text(max_size=4), number=st.integers(0, 255), name=st.none(), meaning=MAYBE_TEXT
)
READINGS = st.none() | st.builds(
    ParameterReading,
    code=st.just("A004"),
    raw=st.integers(0, 4000),
    value=st.floats(allow_nan=False),
    unit=st.just("Hz"),
    at=st.floats(0, 1e6),
)


@settings(max_examples=200)
@given(
    st.sampled_from(sorted(LINES)),
    st.builds(
        ServedValues,
        online=st.booleans(),
        sample_age_s=st.none() | st.floats(0, 100),
        state=MAYBE_TEXT,
        running=MAYBE_BOOL,
        tripped=MAYBE_BOOL,
        status_fields=st.none(),
        direction=st.sampled_from([None, "stop", "forward", "reverse"]),
        output_frequency_hz=MAYBE_FLOAT,
        output_current_a=MAYBE_FLOAT,
        output_voltage_v=MAYBE_FLOAT,
        output_torque_percent=MAYBE_FLOAT,
        power_kw=MAYBE_FLOAT,
        set_frequency_hz=MAYBE_FLOAT,
        trip=TRIPS,
        parameters=st.dictionaries(st.sampled_from(["A004", "F002"]), READINGS),
    ),
    st.builds(DeviceFlags, lease=st.booleans(), lapse_pending=st.booleans()),
    st.none() | st.tuples(st.text(max_size=8), st.integers(0, 10)),
)
def test_values_are_each_metric_s_own_reading(
    line: str, values: ServedValues, flags: DeviceFlags, refusal: tuple[str, int] | None
) -> None:
    config = LINES[line]
    device = Device(GatewayDrive(config, 1, get_profile(config.protocol), Lease(5.0)), 3)
    constants = {
        "Info/Protocol": config.protocol,
        "Info/Line": "l",
        "Info/Node": 1,
        "Control/Refusals": 0,
        LAST_REFUSAL: None,
    }
    names = [metric.definition.name for metric in device.metrics]
    expected = [
        constants[name] if name in constants else metric.read(values, flags)
        for name, metric in zip(names, device.metrics, strict=True)
    ]
    if refusal is not None and LAST_REFUSAL in names:
        at = names.index(LAST_REFUSAL)
        expected[at : at + 2] = refusal
    assert device.values(values, flags, refusal) == expected


def test_devices_built_alike_share_their_metrics_each_numbering_them_from_its_base() -> None:
    """One set of metrics for every device of a line's grants and parameters (issue 44);
    each device's aliases are its own all the same: in its births and in what it finds."""
    config = LineConfig("l", "sim://", "sj300", (1, 2), parameters=("A004",))
    profile = get_profile("sj300")
    first, second = (Device(GatewayDrive(config, n, profile, Lease(5.0)), n + 2) for n in (1, 2))
    assert first.metrics is second.metrics
    assert (first.alias_base, second.alias_base) == (3 << 16, 4 << 16)
    values = ServedValues(
        online=True,
        sample_age_s=0.0,
        state=None,
        running=None,
        tripped=None,
        status_fields=None,
        direction=None,
        output_frequency_hz=12.5,
        output_current_a=None,
        output_voltage_v=None,
        output_torque_percent=None,
        power_kw=None,
        set_frequency_hz=None,
        trip=None,
        parameters={},
    )
    for device, node in ((first, 1), (second, 2)):
        births = decode_payload(
            encode_payload(
                1,
                0,
                zip(device.definitions, device.values(values, DeviceFlags(), None), strict=True),
                birth=True,
                alias_base=device.alias_base,
            )
        )
        aliases = [metric.alias for metric in births.metrics]
        assert aliases == [device.alias_base + i for i in range(len(device.metrics))]
        by_name = {metric.name: metric.value for metric in births.metrics}
        assert (by_name["Info/Node"], by_name["Output Frequency"]) == (node, 12.5)
        fifth = device.by_alias(device.alias_base + 5)
        assert fifth is not None
        assert fifth.definition.name == births.metrics[5].name
    assert first.by_alias(second.alias_base + 5) is None
