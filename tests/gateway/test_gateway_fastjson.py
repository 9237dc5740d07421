"""The JSON the gateway writes per sample (gateway.compact_json, orjson) reads back as written.

The MQTT state and the workbench's events are encoded with orjson since
issue 30; these check what a consumer of either relies on: the same values
back through the standard library's parser, keys sorted when asked, a
state message byte for byte as the standard library wrote it, and a
non-finite float as null (the standard library wrote ``NaN``, no JSON).
"""

from __future__ import annotations

import json
import math
import tracemalloc
from typing import Any

from hypothesis import given
from hypothesis import strategies as st

from sj300_async.gateway import compact_json as dumps
from sj300_async.gateway.mqtt import StateMessage

_SCALARS = (
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**63), max_value=2**63 - 1)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text()
)
_VALUES = st.recursive(
    _SCALARS,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(), inner, max_size=4),
    max_leaves=20,
)


@given(_VALUES)
def test_what_is_written_reads_back_the_same(value: Any) -> None:
    assert json.loads(dumps(value)) == value
    assert json.loads(dumps(value, sort_keys=True)) == value


@given(st.dictionaries(st.text(), st.integers(-1000, 1000), min_size=2, max_size=8))
def test_keys_come_sorted_when_asked(value: dict[str, int]) -> None:
    written = json.loads(dumps(value, sort_keys=True))
    assert list(written) == sorted(value)


def test_a_state_message_is_byte_for_byte_what_the_standard_library_wrote() -> None:
    message = StateMessage(
        gateway="plant",
        line="l7",
        node=9,
        protocol="sj300",
        time=1764255000.123456,
        online=True,
        output_frequency_hz=12.34,
        output_current_a=1.5,
        output_voltage_v=80.0,
        direction="forward",
        running=True,
        tripped=False,
        status={"a": "RUNNING", "b": 1},
        parameters={"A004": 60.0, "F002": None},
        state="accelerating",
    )
    body = {name: getattr(message, name) for name in message.__slots__}
    body["parameters"] = dict(message.parameters)
    body["status"] = dict(message.status or {})
    expected = json.dumps(body, separators=(",", ":"), sort_keys=True).encode()
    assert message.to_json() == expected


def test_a_value_that_is_not_finite_is_null() -> None:
    assert dumps({"hz": math.nan, "a": math.inf}) == b'{"hz":null,"a":null}'


def test_what_is_written_holds_no_more_memory_than_its_bytes() -> None:
    """orjson >= 3.12 hands back its writer's buffer (4 KiB at least); kept per drive, that
    was 8 KiB for a 500-byte state. The allocations that outlive the call are traced."""
    document = {f"key{i}": i * 1.5 for i in range(40)}
    dumps(document)  # orjson imported, its first-call state made
    tracemalloc.start()
    try:
        kept = [dumps(document) for _ in range(100)]
        traced, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    size = len(kept[0])
    assert 400 < size < 1000
    assert traced < 100 * (size + 200)  # the list's slots and each bytes' header, no more
