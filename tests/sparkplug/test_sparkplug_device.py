"""A device's values in a sample, sans-IO: Device.values against each metric's own reader.

Device.values reads the state's fields in one call and starts from its
constants (it runs at every sample); whatever the state, it must say what
reading each metric one by one says, the latest refusal in its two metrics.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from sj300_async.gateway import GatewayDrive, Lease, LineConfig, WriteGrant
from sj300_async.gateway.mqtt import StateMessage
from sj300_async.gateway.sparkplug import LAST_REFUSAL, Device
from sj300_async.profiles import get_profile

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


@settings(max_examples=200)
@given(
    st.sampled_from(sorted(LINES)),
    st.builds(
        StateMessage,
        gateway=st.just("gw"),
        line=st.just("l"),
        node=st.just(1),
        protocol=st.just("sj300"),
        time=st.floats(0, 2e9),
        online=st.booleans(),
        output_frequency_hz=MAYBE_FLOAT,
        output_current_a=MAYBE_FLOAT,
        output_voltage_v=MAYBE_FLOAT,
        direction=st.sampled_from([None, "stop", "forward", "reverse"]),
        running=MAYBE_BOOL,
        tripped=MAYBE_BOOL,
        trip=MAYBE_TEXT,
        set_frequency_hz=MAYBE_FLOAT,
        output_torque_percent=MAYBE_FLOAT,
        power_kw=MAYBE_FLOAT,
        parameters=st.dictionaries(st.sampled_from(["A004", "F002"]), MAYBE_FLOAT),
        state=MAYBE_TEXT,
        trip_meaning=MAYBE_TEXT,
        lapse_pending=st.booleans(),
    ),
    st.booleans(),
    st.none() | st.tuples(st.text(max_size=8), st.integers(0, 10)),
)
def test_values_are_each_metric_s_own_reading(
    line: str, state: StateMessage, lease: bool, refusal: tuple[str, int] | None
) -> None:
    config = LINES[line]
    device = Device(GatewayDrive(config, 1, get_profile(config.protocol), Lease(5.0)), 3)
    expected = [metric.read(state, lease) for metric in device.metrics]
    names = [metric.definition.name for metric in device.metrics]
    if refusal is not None and LAST_REFUSAL in names:
        at = names.index(LAST_REFUSAL)
        expected[at : at + 2] = refusal
    assert device.values(state, lease, refusal) == expected
