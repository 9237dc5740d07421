"""The workbench's sans-IO parts: the trend's ring buffer and the event hub's coalescing."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sj300_async.gateway._trend import (
    BLOCK,
    SAMPLE_BYTES,
    Trend,
    millisecond,
    trend_capacity,
)
from sj300_async.gateway.http._events import EventHub, sse_frame


def test_the_capacity_covers_the_window_with_a_margin() -> None:
    assert trend_capacity(900, 0.5) == 1980
    assert trend_capacity(60, 0.1) == 660
    assert trend_capacity(1, 10) == 2  # never fewer than two samples


def test_a_trend_keeps_the_newest_samples_oldest_first() -> None:
    trend = Trend(3)
    for at in (1.0, 2.0, 3.0, 4.0, 5.0):
        assert trend.add(at, at * 10, at, None)
    columns = trend.columns()
    assert columns == {
        "time": [3.0, 4.0, 5.0],
        "output_frequency_hz": [30.0, 40.0, 50.0],
        "output_current_a": [3.0, 4.0, 5.0],
        "output_voltage_v": [None, None, None],  # not reported: NaN inside, null outside
    }
    assert trend.columns(since=4.0)["time"] == [5.0]
    assert len(trend) == 3


def test_a_sample_not_newer_than_the_last_is_not_kept() -> None:
    trend = Trend(4)
    assert trend.add(2.0, 1.0, 1.0, 1.0)
    assert not trend.add(2.0, 9.0, 9.0, 9.0)
    assert not trend.add(1.0, 9.0, 9.0, 9.0)
    assert trend.columns()["output_frequency_hz"] == [1.0]


def test_float32_values_come_back_as_the_decimal_written() -> None:
    trend = Trend(2)
    trend.add(1.0, 49.99, 12.3, 398.7)
    columns = trend.columns()
    assert columns["output_frequency_hz"] == [49.99]
    assert columns["output_current_a"] == [12.3]
    assert columns["output_voltage_v"] == [398.7]


def test_a_ramp_is_held_in_a_sixth_of_its_plain_bytes() -> None:
    """A drive ramping, its current and voltage wavering: its varint steps, sealed, take a
    sixth of the 16 bytes a sample plainly held, or less (the CHANGELOG has the figures)."""
    trend = Trend(1980)
    for at in range(5000):
        wobble = (at * 7919) % 5  # a reading's last digit, moving
        trend.add(1_764_763_200 + at * 0.5, at * 0.01, 12.3 + wobble / 10, 398.0 + wobble / 10)
    assert len(trend) == 1980
    assert trend.nbytes < 1980 * SAMPLE_BYTES / 6
    columns = trend.columns()
    assert columns["output_frequency_hz"][-1] == 49.99
    assert len(columns["time"]) == 1980


def test_noise_is_never_held_in_more_than_its_plain_bytes_and_a_block() -> None:
    trend = Trend(256)
    value = 1
    for at in range(2000):
        value = value * 1_103_515_245 % 2**31  # every bit moving
        trend.add(float(at), value / 1000, -value / 1000, (value >> 8) / 1000)
    assert trend.nbytes <= (256 + 2 * BLOCK) * 5 * 4  # its steps, as they are
    assert trend.columns()["output_current_a"][-1] == -value / 1000


@given(
    st.lists(
        st.one_of(st.none(), st.floats(-2_147_483.647, 2_147_483.647), st.sampled_from([1e9])),
        min_size=1,
        max_size=3 * BLOCK,
    )
)
def test_every_value_comes_back_through_the_varints_whatever_its_step(
    values: list[float | None],
) -> None:
    # Steps from a value to "not reported" (-2**31 thousandths) and back are the widest.
    trend = Trend(len(values))
    for at, value in enumerate(values):
        trend.add(1_764_763_200.0 + at, value, None if value is None else -value, value)
    expected = [None if v is None or abs(v) > 2_147_483.647 else round(v * 1000) / 1000
                for v in values]  # fmt: skip
    columns = trend.columns()
    assert columns["output_frequency_hz"] == expected
    assert columns["output_current_a"] == [None if v is None else -v for v in expected]


def test_a_trend_holds_at_least_one_sample() -> None:
    with pytest.raises(ValueError, match="at least one"):
        Trend(0)


@given(st.integers(1, 20), st.lists(st.floats(0, 1e6, allow_nan=False), max_size=60))
def test_the_ring_is_the_tail_of_the_increasing_samples(capacity: int, times: list[float]) -> None:
    trend = Trend(capacity)
    kept: list[float] = []
    for at in times:
        if trend.add(at, 1.0, 1.0, 1.0):
            kept.append(millisecond(at))
    assert kept == sorted(set(kept))
    assert trend.columns()["time"] == kept[-capacity:]


def test_times_are_kept_to_the_millisecond_as_served() -> None:
    trend = Trend(4)
    assert trend.add(1_764_763_323.4561, 1.0, 1.0, 1.0)
    assert not trend.add(1_764_763_323.4564, 2.0, 2.0, 2.0)  # the same millisecond
    assert trend.add(1_764_763_323.4576, 3.0, 3.0, 3.0)
    assert trend.columns()["time"] == [1_764_763_323.456, 1_764_763_323.458]
    assert trend.last_time == millisecond(1_764_763_323.4576)


def test_samples_weeks_apart_are_kept_as_they_came() -> None:
    trend = Trend(3)
    times = [1_700_000_000.123 + day * 86_400.0 for day in (0, 20, 40, 60, 80)]
    for at in times:
        assert trend.add(at, 1.0, 1.0, 1.0)
    assert trend.columns()["time"] == [millisecond(t) for t in times[-3:]]
    assert trend.columns(since=millisecond(times[3]))["time"] == [millisecond(times[4])]


@given(st.integers(1, 150), st.integers(0, 400))
def test_across_blocks_the_newest_capacity_samples_are_served(capacity: int, count: int) -> None:
    trend = Trend(capacity)
    for at in range(count):
        assert trend.add(1000.0 + at, at / 100, None if at % 3 else at / 10, 230.0)
    columns = trend.columns()
    kept = list(range(max(0, count - capacity), count))
    assert columns["time"] == [1000.0 + at for at in kept]
    assert columns["output_frequency_hz"] == [at / 100 for at in kept]
    assert columns["output_current_a"] == [None if at % 3 else at / 10 for at in kept]
    assert len(trend) == len(kept)
    if kept:
        middle = 1000.0 + kept[len(kept) // 2]
        newer = [t for t in columns["time"] if t is not None and t > middle]
        assert trend.columns(since=middle)["time"] == newer


def test_the_hub_sends_the_latest_frame_of_each_subject_and_counts_the_rest() -> None:
    hub = EventHub()
    fast, slow = hub.open(), hub.open()
    hub.publish("drive/a/1", b"one\n\n")
    assert fast._pending == {"drive/a/1": b"one\n\n"}
    fast._pending.clear()
    hub.publish("drive/a/1", b"two\n\n")
    hub.publish("drive/a/2", b"other\n\n")
    # the slow stream still had "one": replaced where it stood, by "two"
    assert list(slow._pending.items()) == [("drive/a/1", b"two\n\n"), ("drive/a/2", b"other\n\n")]
    assert hub.replaced == 1
    hub.discard(slow)
    assert len(hub) == 1
    assert slow.closed


async def test_a_stream_takes_its_frames_as_one_chunk() -> None:
    hub = EventHub()
    stream = hub.open()
    assert await stream.take(0.01) == b""  # nothing came in time
    hub.publish("line/x", b"a\n\n")
    hub.publish("drive/x/1", b"b\n\n")
    assert await stream.take(1) == b"a\n\nb\n\n"
    assert hub.sent == 2
    hub.close()
    assert await stream.take(1) is None


def test_an_event_is_one_json_line() -> None:
    frame = sse_frame("drive", {"state": "tripped\nE07", "x": 1.5})
    name, data, end = frame.split(b"\n", 2)
    assert name == b"event: drive"
    assert json.loads(data.removeprefix(b"data: ")) == {"state": "tripped\nE07", "x": 1.5}
    assert end == b"\n"
    # never "NaN" on the wire (JSON has none): unknown, as the page shows a missing value
    assert sse_frame("drive", {"x": math.nan}) == b'event: drive\ndata: {"x":null}\n\n'


async def test_a_batch_put_without_waking_is_sent_whole_at_the_flush() -> None:
    """A drive's frames wait for the gateway's batch to end (its flush), then go in one
    write; the stream keeps no timer of its own (issue 42)."""
    hub = EventHub()
    stream = hub.open()
    hub.publish("drive/x/1", b"a\n\n", wake=False)
    hub.publish("drive/x/2", b"b\n\n", wake=False)
    assert await stream.take(0.01) == b""  # not woken: the batch is not whole yet
    hub.flush()
    assert await stream.take(0.01) == b"a\n\nb\n\n"
    hub.flush()  # nothing pending: no wake, no empty write
    assert await stream.take(0.01) == b""
