"""A drive as served (gateway/_served.py): the one judgement every northbound serves."""

from __future__ import annotations

import dataclasses
import math
from types import MappingProxyType

import pytest

from sj300_async.gateway import (
    DIRECTION_WORDS,
    GatewayDrive,
    Lease,
    LineConfig,
    Quality,
    ServedDrive,
)
from sj300_async.profiles import DriveSnapshot, ParameterReading, Trip, TripLog, get_profile
from sj300_async.wire import Direction

STALE_S = 5.0
NOW = 1000.0


def _line(**changes: object) -> LineConfig:
    return LineConfig(name="hall", url="sim://", protocol="sj300", nodes=(1,), **changes)  # type: ignore[arg-type]


def _trip() -> Trip:
    return Trip(code="E07", number=7, name="OVER_VOLTAGE", meaning="over-voltage")


def _snapshot(**changes: object) -> DriveSnapshot:
    """Drive 1, read in full at NOW, running forward at 30 Hz, tripped history of one."""
    base = DriveSnapshot(
        line="hall",
        node=1,
        protocol="sj300",
        unit=1,
        taken_at=NOW,
        time=1.7e9,
        online=True,
        last_ok=NOW,
        status_at=NOW,
        running=True,
        tripped=False,
        state="running",
        status_fields=MappingProxyType({"running": True}),
        monitor_at=NOW,
        output_frequency_hz=30.0,
        output_current_a=2.5,
        output_voltage_v=200.0,
        direction=Direction.FORWARD,
        direction_at=NOW,
        set_frequency_hz=30.0,
        set_frequency_at=NOW,
        trips=TripLog(total_count=1, records=(_trip(),)),
        trips_at=NOW,
        parameters=MappingProxyType(
            {"A004": ParameterReading("A004", 6000, 60.0, "Hz", NOW - 4.0)}
        ),
    )
    return dataclasses.replace(base, **changes)  # type: ignore[arg-type]


def test_quality_is_offline_then_never_then_unavailable_then_stale_then_good() -> None:
    served = ServedDrive(_snapshot(), stale_after_s=STALE_S)
    assert served.quality("monitor", NOW) is Quality.GOOD
    assert served.quality("monitor", NOW + STALE_S) is Quality.GOOD  # the deadline itself
    assert served.quality("monitor", NOW + STALE_S + 0.001) is Quality.STALE
    assert served.quality("monitor", NOW, present=False) is Quality.UNAVAILABLE
    never = ServedDrive(_snapshot(monitor_at=-math.inf), stale_after_s=STALE_S)
    assert never.quality("monitor", NOW, present=False) is Quality.NEVER
    offline = ServedDrive(_snapshot(online=False, monitor_at=-math.inf), stale_after_s=STALE_S)
    assert offline.quality("monitor", NOW) is Quality.OFFLINE


def test_before_the_first_sample_a_value_is_waited_for_not_offline() -> None:
    # A new drive's first snapshot: no verdict yet (its readings say not online).
    first = GatewayDrive(_line(), 1, get_profile("sj300"), Lease(5.0)).served
    assert first.snapshot.taken_at == -math.inf
    assert not first.snapshot.online
    assert first.quality("status", 0.0) is Quality.NEVER
    assert first.parameter_quality("A004", 0.0) is Quality.NEVER
    assert first.values(0.0).online is False


def test_the_trip_history_has_its_read_interval_beyond_stale_after() -> None:
    served = ServedDrive(_snapshot(), stale_after_s=STALE_S, trips_interval_s=30.0)
    assert served.fresh("trips", NOW + 34.0)
    assert not served.fresh("trips", NOW + 36.0)
    assert not served.fresh("status", NOW + 6.0)  # the others have none


def test_values_are_masked_group_by_group_and_the_direction_is_a_word() -> None:
    snapshot = _snapshot(monitor_at=NOW - 10.0, direction_at=NOW - 10.0)
    values = ServedDrive(snapshot, stale_after_s=STALE_S).values()
    assert (values.state, values.running, values.tripped) == ("running", True, False)
    assert (values.output_frequency_hz, values.output_current_a, values.direction) == (
        None,
        None,
        None,
    )
    assert values.set_frequency_hz == 30.0
    fresh = ServedDrive(_snapshot(), stale_after_s=STALE_S).values()
    assert fresh.direction == DIRECTION_WORDS[Direction.FORWARD] == "forward"
    assert fresh.output_frequency_hz == 30.0


def test_values_at_the_sample_are_built_once_and_a_reader_gets_them_at_its_time() -> None:
    served = ServedDrive(_snapshot(), stale_after_s=STALE_S)
    assert served.values() is served.values()
    later = served.values(NOW + 6.0)
    assert later.running is None
    assert later.output_frequency_hz is None
    assert later.sample_age_s == pytest.approx(6.0)
    assert served.values().running is True


def test_a_parameter_stale_or_refused_is_none_and_one_never_read_is_left_out() -> None:
    snapshot = _snapshot(unavailable_parameters=frozenset({"b012"}))
    served = ServedDrive(snapshot, stale_after_s=STALE_S)
    assert served.values().parameters["A004"] is snapshot.parameters["A004"]
    assert dict(served.values(NOW + 1.5).parameters) == {"A004": None, "b012": None}
    assert "F002" not in served.values().parameters
    assert served.parameter_quality("A004", NOW) is Quality.GOOD
    assert served.parameter_quality("A004", NOW + 1.5) is Quality.STALE
    assert served.parameter_quality("b012", NOW) is Quality.UNAVAILABLE
    assert served.parameter_quality("F002", NOW) is Quality.NEVER


def test_the_trip_is_served_only_while_a_fresh_status_says_tripped() -> None:
    trip = _trip()
    tripped = _snapshot(tripped=True, running=False, state="tripped", trip=trip)
    served = ServedDrive(tripped, stale_after_s=STALE_S)
    assert served.values().trip is trip
    assert served.values(NOW + 6.0).trip is None
    assert ServedDrive(_snapshot(trip=trip), stale_after_s=STALE_S).values().trip is None


def test_the_lease_is_read_live_and_the_lapse_as_of_the_snapshot() -> None:
    lease = Lease(3.0)
    served = ServedDrive(_snapshot(), stale_after_s=STALE_S, lease=lease, lapse_pending=True)
    assert served.lease_holder(NOW) is None
    assert served.lease_seconds_left(NOW) == 0.0
    lease.holder, lease.expires_at = "10.0.0.5", NOW + 3.0
    assert served.lease_holder(NOW + 1.0) == "10.0.0.5"
    assert served.lease_seconds_left(NOW + 1.0) == pytest.approx(2.0)
    assert served.lease_holder(NOW + 3.0) is None
    assert served.lapse_pending


def test_a_gateway_drive_serves_each_snapshot_it_builds() -> None:
    drive = GatewayDrive(
        _line(trips_interval_s=30.0), 1, get_profile("sj300"), Lease(5.0),
        stale_after_s=2.0,
    )  # fmt: skip
    drive.lapse_pending = True
    snapshot = drive.rebuild(NOW, wall=1.7e9)
    assert drive.served.snapshot is snapshot
    assert drive.served.stale_after_s == 2.0
    assert drive.served.lapse_pending
    assert drive.served.fresh_until("trips") == -math.inf  # never read


def test_a_snapshot_rebuilt_before_the_first_poll_is_not_offline() -> None:
    # A write's read-back can rebuild a drive's snapshot before the poller's first verdict.
    drive = GatewayDrive(_line(), 1, get_profile("sj300"), Lease(5.0))
    drive.rebuild(NOW, wall=1.7e9)
    assert not drive.snapshot.online  # the readings' default: no verdict, not "offline"
    assert drive.served.quality("status", NOW) is Quality.NEVER
    assert drive.served.parameter_quality("A004", NOW) is Quality.NEVER


def test_the_verdict_itself_is_never_offline_and_ages_with_the_sample() -> None:
    # An offline drive's verdict is a good verdict: "offline" is its value, not its quality.
    offline = ServedDrive(_snapshot(online=False), stale_after_s=STALE_S)
    assert offline.verdict_quality(NOW) is Quality.GOOD
    assert offline.sample_until == NOW + STALE_S
    assert offline.verdict_quality(NOW + STALE_S) is Quality.GOOD
    assert offline.verdict_quality(NOW + STALE_S + 0.001) is Quality.STALE  # a stalled poller
    first = GatewayDrive(_line(), 1, get_profile("sj300"), Lease(5.0)).served
    assert first.verdict_quality(0.0) is Quality.NEVER
    assert first.verdict is False  # its online is not the poller's verdict yet
    assert offline.verdict is True
