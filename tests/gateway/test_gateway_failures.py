"""A northbound that fails keeps its failure: the others, the writes, the trip reader go on.

A northbound registered here (``breaking``) raises from ``publish`` every
time; a second one (``recording``) keeps what it gets. Registered after the
breaking one, the recorder would get nothing if the gateway let the first
failure through. Also here: the state right after a command pairs the new
status with a direction read after it (the monitor is read back too).
"""

from __future__ import annotations

import asyncio
import logging
import textwrap
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import pytest
from waiting import wait_for

from sj300_async.gateway import (
    ConfigTable,
    Endpoint,
    GatewayView,
    Heartbeat,
    Northbound,
    RunCommand,
    SectionContext,
    ServedDrive,
    SetFrequency,
    register_northbound,
    unregister_northbound,
)
from sj300_async.profiles import DriveSnapshot
from sj300_async.wire import Direction

from .conftest import drive_of, polled, running_gateway

if TYPE_CHECKING:
    from prometheus_client.core import Metric


@dataclass
class _Recorder:
    breaks: bool
    got: list[DriveSnapshot] = field(default_factory=list)

    async def start(self, gateway: GatewayView) -> None:
        pass

    def announce(self) -> str | None:
        return None

    def publish(self, served: ServedDrive) -> None:
        snapshot = served.snapshot
        if self.breaks:
            raise OSError("the northbound's disk is full")
        self.got.append(snapshot)

    def metrics(self) -> Iterable[Metric]:
        return ()

    async def close(self) -> None:
        pass


@dataclass
class _Spec:
    section: str
    breaks: bool
    keys: Sequence[str] = ()
    flag: None = None
    requires: Sequence[str] = ()
    made: list[_Recorder] = field(default_factory=list)

    def parse(self, table: ConfigTable, context: SectionContext) -> object:
        return self.section

    def endpoints(self, config: object) -> Sequence[tuple[str, Endpoint]]:
        return ()

    def create(self, config: object) -> Northbound:
        recorder = _Recorder(self.breaks)
        self.made.append(recorder)
        return recorder


@pytest.fixture
def northbounds() -> Iterator[tuple[_Spec, _Spec]]:
    breaking, recording = _Spec("breaking", True), _Spec("recording", False)
    register_northbound("breaking", breaking)
    register_northbound("recording", recording)
    try:
        yield breaking, recording
    finally:
        unregister_northbound("breaking")
        unregister_northbound("recording")


def _toml(interval_s: float) -> str:
    return textwrap.dedent(
        f"""
        [breaking]
        [recording]
        [[lines]]
        name = "hall"
        url = "sim://?nodes=1-2"
        nodes = "1-2"
        interval_s = {interval_s}
        trips_interval_s = 0.05
        parameters = ["F001"]
        [[lines.writes]]
        nodes = "1"
        control = true
        """
    )


async def test_a_failing_northbound_costs_only_itself(
    northbounds: tuple[_Spec, _Spec], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG, logger="sj300_async.gateway")
    _, recording = northbounds
    async with running_gateway(_toml(0.05)) as gateway:
        await polled(gateway)
        recorder = recording.made[0]
        await wait_for(lambda: len(recorder.got) >= 6, "the second northbound gets snapshots")
        drive = drive_of(gateway, "hall", 1)
        # A write goes through, is audited, and its read-back reaches the recorder.
        assert (await gateway.write("10.0.0.9", drive, Heartbeat())).ok
        before = len(recorder.got)
        result = await gateway.write("10.0.0.9", drive, SetFrequency(12.5))
        assert result.ok, result
        assert gateway.audit.counts == {"ok": 2}  # the heartbeat and the write
        assert any(s.set_frequency_hz == 12.5 for s in recorder.got[before:])
        # The trip reader goes on: a trip injected now is read, and reaches the recorder.
        simulator = gateway.lines[0].bus.simulator
        assert simulator is not None
        simulator.drives[2].trip(7, now=asyncio.get_running_loop().time())
        await wait_for(
            lambda: any(s.node == 2 and s.trip is not None for s in recorder.got),
            "the trip is read and shown",
        )
        # Both got every snapshot: the first failed to take each one, the second took it.
        assert gateway.publish_errors["breaking"] == len(recorder.got)
    failures = [r for r in caplog.records if "failed to take a snapshot" in r.getMessage()]
    assert failures[0].levelno == logging.ERROR  # once, with its traceback
    assert failures[0].exc_info
    assert all(r.levelno == logging.DEBUG for r in failures[1:])


async def test_the_state_after_a_command_pairs_its_status_with_a_fresh_direction(
    northbounds: tuple[_Spec, _Spec],
) -> None:
    _, recording = northbounds
    async with running_gateway(_toml(30.0)) as gateway:  # no poll after the first
        await polled(gateway)
        drive = drive_of(gateway, "hall", 1)
        assert drive.snapshot.direction == Direction.STOP
        for request in (Heartbeat(), SetFrequency(20.0), RunCommand(Direction.REVERSE)):
            assert (await gateway.write("10.0.0.9", drive, request)).ok, request
        shown = recording.made[0].got[-1]
        assert (shown.running, shown.direction) == (True, Direction.REVERSE)
        assert shown.monitor_at >= shown.status_at  # read after the command's status
        assert (await gateway.write("10.0.0.9", drive, RunCommand(Direction.STOP))).ok
        shown = recording.made[0].got[-1]
        assert shown.monitor_at >= shown.status_at


async def test_every_snapshot_made_before_the_gateway_stops_reaches_the_northbounds(
    northbounds: tuple[_Spec, _Spec],
) -> None:
    """Snapshots are gathered before the northbounds take them (gateway/_batch.py): those
    gathered when the gateway stops are delivered before the northbounds close."""
    _, recording = northbounds
    made: list[DriveSnapshot] = []
    async with running_gateway(_toml(0.05)) as gateway:
        await polled(gateway)
        recorder = recording.made[0]
        publish = gateway._publish

        def counted(served: ServedDrive) -> None:
            made.append(served.snapshot)
            publish(served)

        gateway._publish = counted  # type: ignore[method-assign]
        await wait_for(lambda: len(made) >= 4, "snapshots made")
        await wait_for(lambda: len(gateway._batch) > 0, "snapshots gathered, not delivered")
        stopping_with = list(made)
        delivered = len(recorder.got)
    at = {id(snapshot): i for i, snapshot in enumerate(recorder.got)}
    assert all(id(snapshot) in at for snapshot in stopping_with)
    positions = [at[id(snapshot)] for snapshot in stopping_with]
    assert positions == sorted(positions)  # in the order they were made
    assert max(positions) >= delivered  # the gathered ones came as the gateway stopped
