"""A device's values in a sample, sans-IO: Device.values against each metric's own reader.

Device.values reads the served values' fields in one call and starts from
its constants (it runs at every sample); whatever the drive as served, it
must say what reading each metric one by one says, the latest refusal in
its two metrics.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from sj300_async.gateway import GatewayDrive, Lease, LineConfig, ServedValues, WriteGrant
from sj300_async.gateway.sparkplug import LAST_REFUSAL, Device, DeviceFlags
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
    expected = [metric.read(values, flags) for metric in device.metrics]
    names = [metric.definition.name for metric in device.metrics]
    if refusal is not None and LAST_REFUSAL in names:
        at = names.index(LAST_REFUSAL)
        expected[at : at + 2] = refusal
    assert device.values(values, flags, refusal) == expected
