"""The OPC UA address space through asyncua's client: the model, values, time, quality, changes."""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any, cast

import pytest
from asyncua import Client, ua
from waiting import wait_for

from sj300_async.gateway import GatewayDrive, Quality, ServedDrive
from sj300_async.gateway.opcua._model import Binding, DriveNodes
from sj300_async.gateway.opcua._quality import QUALITY_STATUS
from sj300_async.gateway.opcua._sources import (
    ONLINE,
    SETPOINT,
    TRIP_COUNT,
    Source,
    parameter_source,
)
from sj300_async.profiles import DriveSnapshot, ParameterReading, TripLog
from sj300_async.simulator.sj300 import SimulatedBus

from .conftest import (
    NAMESPACE,
    PASSWORD,
    USER,
    Pair,
    connected,
    opcua_gateway,
    opcua_toml,
    tcp_line,
)

HZ_UNIT_ID = (ord("H") << 16) | (ord("T") << 8) | ord("Z")


async def _namespace(client: Client) -> int:
    index: int = await client.get_namespace_index(NAMESPACE)
    return index


#: The trip history's arrays under each drive's Logbook.
TRIP_ARRAYS = (
    "TripCodes", "TripMeanings", "TripOutputFrequencies", "TripOutputCurrents",
    "TripOutputVoltages",
)  # fmt: skip


def _var(client: Client, ns: int, path: str) -> Any:
    return client.get_node(ua.NodeId(path, ns))


async def _names(node: Any) -> set[str]:
    return {(await child.read_browse_name()).Name for child in await node.get_children()}


async def test_the_model_follows_opc_40400_with_units_and_ranges(tmp_path: Path) -> None:
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (_, server),
        connected(server.url) as client,
    ):
        ns = await _namespace(client)
        lines = await client.nodes.objects.get_child([f"{ns}:Lines"])
        assert await _names(lines) == {"hall"}
        hall = await lines.get_child([f"{ns}:hall"])
        assert {"Drive1", "Drive2", "Drive3", "Drive4", "Protocol", "Url", "Requests"} <= (
            await _names(hall)
        )
        drive = _var(client, ns, "hall/Drive1")
        assert {"Monitoring", "Logbook", "Parameters", "Online", "Line", "Node", "Protocol"} <= (
            await _names(drive)
        )
        assert {"TakeControl", "Run", "Stop", "SetFrequency"} <= await _names(drive)
        # Drive 3's line grants it nothing: no methods, no writable parameter.
        assert not {"TakeControl", "Run", "Stop", "SetFrequency"} & await _names(
            _var(client, ns, "hall/Drive3")
        )
        monitoring = _var(client, ns, "hall/Drive1/Monitoring")
        assert {
            "ConverterOutputFrequency", "FrequencyCommandValue", "ConverterOutputCurrent",
            "ConverterOutputVoltage", "ShaftTurningDirection", "Running", "Tripped", "State",
        } <= await _names(monitoring)  # fmt: skip
        frequency = _var(client, ns, "hall/Drive1/Monitoring/ConverterOutputFrequency")
        eu = await (await frequency.get_child(["0:EngineeringUnits"])).read_value()
        assert (eu.UnitId, eu.DisplayName.Text) == (HZ_UNIT_ID, "Hz")
        assert eu.NamespaceUri == "http://www.opcfoundation.org/UA/units/un/cefact"
        hz_range = await (await frequency.get_child(["0:EURange"])).read_value()
        assert (hz_range.Low, hz_range.High) == (0.0, 400.0)  # SJ300's highest
        assert await frequency.read_type_definition() == ua.NodeId(17497)  # AnalogUnitType
        assert await frequency.read_data_type() == ua.NodeId(ua.ObjectIds.Double)
        amps = await _var(client, ns, "hall/Drive1/Monitoring/ConverterOutputCurrent").get_child(
            ["0:EngineeringUnits"]
        )
        assert (await amps.read_value()).DisplayName.Text == "A"
        direction = _var(client, ns, "hall/Drive1/Monitoring/ShaftTurningDirection")
        states = await (await direction.get_child(["0:EnumStrings"])).read_value()
        assert [text.Text for text in states] == ["stopped", "forward", "reverse"]
        # The parameters in their units, with the catalogue's range; F002 granted.
        a004 = _var(client, ns, "hall/Drive1/Parameters/A004")
        assert (await (await a004.get_child(["0:EngineeringUnits"])).read_value()).UnitId == (
            HZ_UNIT_ID
        )
        access = await _var(client, ns, "hall/Drive1/Parameters/F002").read_attribute(
            ua.AttributeIds.AccessLevel
        )
        assert access.Value.Value & ua.AccessLevel.CurrentWrite.mask
        access = await a004.read_attribute(ua.AttributeIds.AccessLevel)
        assert not access.Value.Value & ua.AccessLevel.CurrentWrite.mask
        # The trip history, one array per field.
        logbook = _var(client, ns, "hall/Drive1/Logbook")
        assert await _names(logbook) == {"ActiveTrip", "TripCount", *TRIP_ARRAYS}
        frequencies = _var(client, ns, "hall/Drive1/Logbook/TripOutputFrequencies")
        rank = await frequencies.read_attribute(ua.AttributeIds.ValueRank)
        assert rank.Value.Value == ua.ValueRank.OneDimension
        dims = await frequencies.read_attribute(ua.AttributeIds.ArrayDimensions)
        assert dims.Value.Value == [0]
        assert (await frequencies.read_data_type()) == ua.NodeId(ua.ObjectIds.Double)
        units = await (await frequencies.get_child(["0:EngineeringUnits"])).read_value()
        assert units.UnitId == HZ_UNIT_ID
        # 212 with 4 drives (the line, its folder and counters included); 101 per drive
        # when each trip record was an object.
        assert 4 * 40 < server.node_count < 4 * 60


async def test_values_carry_the_time_they_were_read_and_good_quality(tmp_path: Path) -> None:
    async with opcua_gateway(opcua_toml(tmp_path)) as (gateway, server):
        drive = gateway.drive("hall", 1)
        assert drive is not None
        await wait_for(lambda: drive.snapshot.last_ok is not None, "a first sample")
        async with connected(server.url) as client:
            ns = await _namespace(client)
            before = time.time()
            value = await _var(
                client, ns, "hall/Drive1/Monitoring/ConverterOutputVoltage"
            ).read_data_value()
            snapshot = drive.snapshot
            assert value.StatusCode.is_good()
            assert value.Value.Value == snapshot.output_voltage_v
            source: datetime = value.SourceTimestamp
            served: datetime = value.ServerTimestamp
            # Read from the drive at the monitor read, before it was served.
            assert source.timestamp() <= served.timestamp()
            assert source.timestamp() <= before
            assert before - source.timestamp() < 1.0
            assert (await _var(client, ns, "hall/Drive1/Online").read_value()) is True
            state = await _var(client, ns, "hall/Drive1/Monitoring/State").read_value()
            assert state == snapshot.state_text() == "stopped"
            properties = [
                await _var(client, ns, f"hall/Drive1/{name}").read_value()
                for name in ("Line", "Node", "Protocol", "UnitId")
            ]
            assert properties == ["hall", 1, "sj300", 1]
            requests = await _var(client, ns, "hall/Requests").read_value()
            assert requests > 0
            # A polled parameter in its unit.
            a004 = await _var(client, ns, "hall/Drive1/Parameters/A004").read_data_value()
            assert a004.StatusCode.is_good()
            assert a004.Value.Value == snapshot.parameters["A004"].value
            # The trip history, once read: none recorded is an empty array, Good.
            await wait_for(lambda: drive.snapshot.trips is not None, "the trip history read")
            codes = await _var(client, ns, "hall/Drive1/Logbook/TripCodes").read_data_value()
            assert codes.StatusCode.is_good()
            assert codes.Value.Value == []


async def test_the_trip_history_reads_newest_first_one_array_per_field(tmp_path: Path) -> None:
    async with tcp_line() as (sim, url):
        text = opcua_toml(tmp_path, url=url, line_extra="trips_interval_s = 0.2")
        async with opcua_gateway(text) as (gateway, server), connected(server.url) as client:
            ns = await _namespace(client)
            drive = gateway.drive("hall", 2)
            assert drive is not None
            await wait_for(lambda: drive.snapshot.trips is not None, "the trip history read")
            loop = asyncio.get_running_loop()
            assert sim.drives[2].trip(7, now=loop.time())  # E07 over-voltage
            await wait_for(
                lambda: drive.snapshot.trips is not None and drive.snapshot.trips.records,
                "the trip in the history",
            )
            records = drive.snapshot.trips.records  # type: ignore[union-attr]
            values = {
                name: (await _var(client, ns, f"hall/Drive2/Logbook/{name}").read_value())
                for name in TRIP_ARRAYS
            }
        assert values["TripCodes"] == [r.code for r in records]
        assert values["TripCodes"][0] == "E07"
        assert values["TripMeanings"][0] == "over-voltage"
        for name, field in (("TripOutputFrequencies", "output_frequency_hz"),
                            ("TripOutputCurrents", "output_current_a"),
                            ("TripOutputVoltages", "output_voltage_v")):  # fmt: skip
            expected = [getattr(r, field) for r in records]
            served = values[name]
            assert len(served) == len(expected)
            for got, want in zip(served, expected, strict=True):  # NaN: not recorded
                assert math.isnan(got) if want is None else got == pytest.approx(want)


@dataclass
class _Silenceable:
    """A gateway whose line's drives a test can silence: drive 3, seen by a client."""

    sim: SimulatedBus
    client: Client
    namespace: int
    drive: GatewayDrive

    def voltage(self) -> Any:
        return _var(self.client, self.namespace, "hall/Drive3/Monitoring/ConverterOutputVoltage")


@contextlib.asynccontextmanager
async def _silenceable(tmp_path: Path) -> AsyncIterator[_Silenceable]:
    """Values stale after 0.3 s, a drive's silence a time-out after 0.4 s; drive 3 sampled."""
    async with tcp_line() as (sim, url):
        text = opcua_toml(
            tmp_path, url=url, gateway_extra="stale_after_s = 0.3", line_extra="timeout_s = 0.4"
        )
        async with opcua_gateway(text) as (gateway, server), connected(server.url) as client:
            drive = gateway.drive("hall", 3)
            assert drive is not None
            await wait_for(lambda: drive.snapshot.last_ok is not None, "a first sample")
            yield _Silenceable(sim, client, await _namespace(client), drive)


async def test_a_subscription_sees_a_silent_drive_s_value_age(tmp_path: Path) -> None:
    """Between samples only time changes a value's status: the tick pushes Good ->
    Uncertain past stale_after_s, no sample coming to do it (the value's going Bad once
    the poller gives up is the next test's, by reads)."""
    async with _silenceable(tmp_path) as line:
        statuses: list[int] = []

        class Statuses:
            def datachange_notification(self, node: Any, value: Any, data: Any) -> None:
                statuses.append(data.monitored_item.Value.StatusCode.value)

        subscription = await line.client.create_subscription(50, Statuses())
        await subscription.subscribe_data_change(line.voltage())
        await wait_for(lambda: statuses == [ua.StatusCodes.Good], "Good first")
        line.sim.faults.silence(3)
        await wait_for(
            lambda: ua.StatusCodes.UncertainLastUsableValue in statuses, "Uncertain pushed"
        )
        assert line.drive.snapshot.online  # aged by the tick: the poller still waits for it
        assert statuses[: statuses.index(ua.StatusCodes.UncertainLastUsableValue)] == [
            ua.StatusCodes.Good
        ]


async def test_a_silent_drive_goes_uncertain_then_bad_no_communication(tmp_path: Path) -> None:
    """Stale past stale_after_s while the poller still waits for it; offline once it gives up."""
    async with _silenceable(tmp_path) as line:
        client, ns, drive, voltage = line.client, line.namespace, line.drive, line.voltage()
        assert (await voltage.read_data_value()).StatusCode.is_good()
        last = drive.snapshot.output_voltage_v
        line.sim.faults.silence(3)
        seen: list[ua.DataValue] = []

        async def status_is(code: int) -> bool:
            value = await voltage.read_data_value(raise_on_bad_status=False)
            seen.append(value)
            return bool(value.StatusCode.value == code)

        deadline = asyncio.get_running_loop().time() + 10
        while not await status_is(ua.StatusCodes.UncertainLastUsableValue):
            assert asyncio.get_running_loop().time() < deadline, seen[-1]
            await asyncio.sleep(0.02)
        assert seen[-1].Value.Value == last  # the last usable value, flagged
        uncertain = len(seen) - 1
        assert drive.snapshot.online  # the poller has not given up yet
        deadline = asyncio.get_running_loop().time() + 20
        while not await status_is(ua.StatusCodes.BadNoCommunication):
            assert asyncio.get_running_loop().time() < deadline, seen[-1]
            await asyncio.sleep(0.05)
        assert seen[-1].Value.Value is None
        assert not drive.snapshot.online
        online = await _var(client, ns, "hall/Drive3/Online").read_data_value()
        assert (online.Value.Value, online.StatusCode.is_good()) == (False, True)
        # Never served as Good again meanwhile.
        assert all(v.StatusCode.value != ua.StatusCodes.Good for v in seen[uncertain:]), [
            (hex(v.StatusCode.value), v.Value.Value) for v in seen[uncertain:]
        ]
        # The others stay online (their values may age while node 3's time-outs
        # hold the line, past this test's short stale_after_s: Uncertain, not Bad).
        other = await _var(client, ns, "hall/Drive2/Monitoring/State").read_data_value(
            raise_on_bad_status=False
        )
        assert not other.StatusCode.is_bad()
        # Its return is test_opcua_node.py's (the poller retries an offline drive
        # on its own schedule: seconds this test need not spend).


class _Notifications:
    """asyncua's subscription handler: every data change with its receive time."""

    def __init__(self) -> None:
        self.changes: list[tuple[Any, float, ua.DataValue]] = []

    def datachange_notification(self, node: Any, value: Any, data: Any) -> None:
        self.changes.append((value, time.time(), data.monitored_item.Value))


async def _three_more_samples(drive: GatewayDrive) -> None:
    """Until the drive has been polled three more times (its line polls every 0.1 s)."""
    polls = drive.snapshot.taken_at
    await wait_for(lambda: drive.snapshot.taken_at > polls + 0.3, "three more samples")


async def test_a_subscription_follows_a_running_drive(tmp_path: Path, client_pair: Pair) -> None:
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (gateway, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as client,
    ):
        ns = await _namespace(client)
        drive = gateway.drive("hall", 1)
        assert drive is not None
        await wait_for(lambda: drive.snapshot.last_ok is not None, "a first sample")
        handler = _Notifications()
        subscription = await client.create_subscription(50, handler)
        frequency = _var(client, ns, "hall/Drive1/Monitoring/ConverterOutputFrequency")
        running = _var(client, ns, "hall/Drive1/Monitoring/Running")
        await subscription.subscribe_data_change([frequency, running])
        await wait_for(lambda: len(handler.changes) >= 2, "the initial values")
        assert {change[0] for change in handler.changes} == {0.0}
        count = len(handler.changes)
        node = _var(client, ns, "hall/Drive1")
        assert await node.call_method(f"{ns}:TakeControl") == 5.0
        await node.call_method(f"{ns}:SetFrequency", ua.Variant(3.0, ua.VariantType.Double))
        await node.call_method(f"{ns}:Run", "forward")
        await wait_for(lambda: any(c[0] is True for c in handler.changes[count:]), "Running: true")
        # Settled, the output reads the setpoint exactly: 2.99 may be a ramp step whose
        # 3.00 follows (seen under load, as a notification after `settled` below).
        await wait_for(
            lambda: any(isinstance(c[0], float) and c[0] == 3.0 for c in handler.changes),
            "the frequency ramped to 3 Hz",
            timeout=15,
        )
        rising = [c for c in handler.changes[count:] if isinstance(c[0], float)]
        assert len(rising) >= 3  # followed, not only the end
        values = [c[0] for c in rising]
        assert values == sorted(values)
        for _, received, data in rising:
            # Each notification's source time is its sample's, before it was received.
            assert data.SourceTimestamp.timestamp() <= received
        # A sample that changes nothing notifies nothing: at 3 Hz the value stands.
        settled = len(handler.changes)
        await _three_more_samples(drive)
        assert [c[0] for c in handler.changes[settled:] if isinstance(c[0], float)] == []
        await node.call_method(f"{ns}:Stop")


async def test_only_watched_values_are_pushed_and_reads_stay_fresh(
    tmp_path: Path, client_pair: Pair
) -> None:
    """Unwatched, a value costs nothing per sample: reads ask its binding, nothing is pushed."""
    async with (
        opcua_gateway(opcua_toml(tmp_path)) as (gateway, server),
        connected(server.url, pair=client_pair, user=USER, password=PASSWORD) as client,
    ):
        ns = await _namespace(client)
        drive = gateway.drive("hall", 1)
        assert drive is not None
        await wait_for(lambda: drive.snapshot.last_ok is not None, "a first sample")
        node = _var(client, ns, "hall/Drive1")
        await node.call_method(f"{ns}:TakeControl")
        await node.call_method(f"{ns}:SetFrequency", ua.Variant(3.0, ua.VariantType.Double))
        await node.call_method(f"{ns}:Run", "forward")
        frequency = _var(client, ns, "hall/Drive1/Monitoring/ConverterOutputFrequency")
        # Ramping, and nobody subscribed: every sample changes it, nothing is pushed.
        await _three_more_samples(drive)
        assert server.pushed == 0
        first = (await frequency.read_data_value()).Value.Value
        handler = _Notifications()
        subscription = await client.create_subscription(50, handler)
        handle = await subscription.subscribe_data_change(frequency)
        await wait_for(lambda: server.pushed > 0, "a pushed value")
        await subscription.unsubscribe(handle)
        pushed = server.pushed
        await _three_more_samples(drive)
        assert server.pushed == pushed  # unwatched again
        later = (await frequency.read_data_value()).Value.Value
        assert first < later <= 3.0  # the read is the latest sample, not the last push
        await node.call_method(f"{ns}:Stop")


async def test_the_trip_history_is_not_stale_within_its_own_read_interval(tmp_path: Path) -> None:
    """Read every trips_interval_s by plan: older than stale_after_s, yet not stale."""
    text = opcua_toml(
        tmp_path, gateway_extra="stale_after_s = 0.3", line_extra="trips_interval_s = 30"
    )
    async with opcua_gateway(text) as (gateway, server), connected(server.url) as client:
        ns = await _namespace(client)
        drive = gateway.drive("hall", 1)
        assert drive is not None
        await wait_for(lambda: drive.snapshot.trips is not None, "a trip history read")
        read_at = drive.snapshot.trips_at
        loop = asyncio.get_running_loop()
        await wait_for(lambda: loop.time() > read_at + 0.6, "the history older than 0.3 s")
        count = await _var(client, ns, "hall/Drive1/Logbook/TripCount").read_data_value()
        assert count.StatusCode.is_good()
        assert count.Value.Value == drive.snapshot.trips.total_count  # type: ignore[union-attr]
        assert drive.snapshot.trips_at == read_at  # not read again meanwhile


def test_each_served_quality_is_worded_as_one_status_code() -> None:
    assert {q.name: ua.StatusCode(code).name for q, code in QUALITY_STATUS.items()} == {
        "GOOD": "Good",
        "STALE": "UncertainLastUsableValue",
        "OFFLINE": "BadNoCommunication",
        "NEVER": "BadWaitingForInitialData",
        "UNAVAILABLE": "BadDataUnavailable",
    }


def _binding(source: Source, served: ServedDrive, parameter: str | None = None) -> Binding:
    read, _, read_group = source
    owner = cast(DriveNodes, None)  # its drive's object: not looked at by a judgement
    binding = Binding(
        ua.NodeId(1, 2), ua.VariantType.Double, read, owner, read_group=read_group,
        parameter=parameter,
    )  # fmt: skip
    binding.take(served)
    return binding


def test_a_value_s_deadline_is_its_group_s_as_served() -> None:
    """The served view's deadlines, not the northbound's: the trip history's has the
    line's trips_interval_s; the set frequency's has no setpoint_interval_s any more (it
    is read twice per stale_after_s: issue 42); the Online verdict's own rule ages with
    its sample."""
    snapshot = DriveSnapshot(
        line="hall", node=1, protocol="sj300", unit=1, taken_at=100.0, time=1e9,
        online=True, last_ok=100.0, set_frequency_at=90.0, set_frequency_hz=3.0,
        trips_at=50.0, trips=TripLog(total_count=0),
        parameters={"A004": ParameterReading("A004", 6000, 60.0, "Hz", 97.0)},
    )  # fmt: skip
    served = ServedDrive(snapshot, stale_after_s=5.0, trips_interval_s=60.0)
    setpoint = _binding(SETPOINT, served)
    trips = _binding(TRIP_COUNT, served)
    online = _binding(ONLINE, served)
    parameter = _binding(parameter_source("A004"), served, "A004")
    assert (setpoint.until, trips.until, online.until, parameter.until) == (95, 115, 105, 102)
    assert setpoint.quality(95.0) is Quality.GOOD
    assert setpoint.quality(100.0) is Quality.STALE
    assert setpoint.status(100.0) == ua.StatusCodes.UncertainLastUsableValue
    assert trips.quality(115.0) is Quality.GOOD
    assert trips.quality(115.5) is Quality.STALE
    assert parameter.quality(102.5) is Quality.STALE
    assert online.quality(105.5) is Quality.STALE
    # Offline: every value of a group Bad, the verdict itself not.
    gone = ServedDrive(
        DriveSnapshot(
            line="hall", node=1, protocol="sj300", unit=1, taken_at=101.0, time=1e9,
            online=False, last_ok=100.0, set_frequency_at=90.0, set_frequency_hz=3.0,
        ),
        stale_after_s=5.0,
    )  # fmt: skip
    setpoint.take(gone)
    online.take(gone)
    assert setpoint.status(101.0) == ua.StatusCodes.BadNoCommunication
    assert (online.value, online.quality(101.0)) == (False, Quality.GOOD)


async def test_before_the_first_sample_values_wait_rather_than_say_offline(tmp_path: Path) -> None:
    async with tcp_line() as (sim, url):
        for node in range(1, 5):
            sim.faults.silence(node)  # the first poll cannot end in a sample yet
        text = opcua_toml(tmp_path, url=url, line_extra="timeout_s = 5.0")
        async with opcua_gateway(text) as (gateway, server), connected(server.url) as client:
            ns = await _namespace(client)
            assert all(d.snapshot.taken_at == -math.inf for d in gateway.drives)
            value = await _var(client, ns, "hall/Drive1/Monitoring/State").read_data_value(
                raise_on_bad_status=False
            )
            assert value.StatusCode.name == "BadWaitingForInitialData"
