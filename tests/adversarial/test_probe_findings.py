"""Attacks found by probing the doors after issue 41's first defences: two addresses
holding every slot, a storm of Home Assistant births (both fixed since), anonymous
subscriptions of 500 items (bounded, not yet within the issue's lag bounds).

Each test starts the plant (``plant.py``: every door, a SCADA heartbeating drive 1's lease
every second under ``lease_s`` = 3), runs one attack from a process of its own at nice 19
over real sockets (``attacker.py``), checks that the attack happened, then asserts the
promise it broke: the loop's lag (p99 under 50 ms, max under 200 ms), the poll's
rate, the lease, or a legitimate client served while it goes on.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
from pathlib import Path

import pytest

from .plant import OPERATOR_IP, Plant, client_pair, plant
from .test_adversarial import _while_healthz

pytestmark = pytest.mark.timeout(240)

#: Addresses of the attacker's own (the whole of 127.0.0.0/8 is on the plant's loopback).
SOURCES = ["127.0.0.10", "127.0.0.11"]
#: [opcua] max_monitored_items_per_address, as the plant leaves it (its default).
ITEMS_PER_ADDRESS = 2_000


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    return client_pair(tmp_path_factory.mktemp("pki"))


async def _modbus_connects(site: Plant, stop: asyncio.Event) -> dict[str, int]:
    """A new Modbus client from the operator's address every 0.25 s until *stop*: it
    connects and reads register 0 of unit 1. What it got each time."""
    got: dict[str, int] = {}
    while not stop.is_set():
        key = "ok"
        try:
            reader, writer = await asyncio.open_connection(
                "127.0.0.1", site.modbus_port, local_addr=(OPERATOR_IP, 0)
            )
            try:
                writer.write(struct.pack(">HHHBBHH", 7, 0, 6, 1, 3, 0, 1))
                if not await asyncio.wait_for(reader.read(100), 2.0):
                    key = "closed"
            finally:
                writer.close()
        except (OSError, TimeoutError) as exc:
            key = type(exc).__name__
        got[key] = got.get(key, 0) + 1
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), 0.25)
    return got


# -- HTTP, Modbus: every slot held from two addresses ------------------------------------


@pytest.mark.attack_alone
async def test_two_addresses_cannot_hold_every_http_slot(tmp_path: Path) -> None:
    async with plant(tmp_path) as site:
        async with site.window() as window:
            report, health = await _while_healthz(
                site,
                site.attack(
                    "held_connections", port=site.http_port, kind="http", sources=SOURCES,
                    per_source=32, hold_s=8.0, every_s=3.0,
                ),
            )  # fmt: skip
        site.assert_unharmed(window[0])  # the loop is fine: the harm is the lock-out
        assert report["opened"] == 64, report
        assert report["alive_at_end"] >= 60, report  # a GET every 3 s: never idle
        # Seen: {'200': 1, 'ServerDisconnectedError': 32}.
        assert set(health) == {"200"}, health


@pytest.mark.attack_alone
async def test_two_addresses_cannot_hold_every_modbus_slot(tmp_path: Path) -> None:
    async with plant(tmp_path) as site:
        stop = asyncio.Event()
        async with site.window() as window:
            probe = asyncio.create_task(_modbus_connects(site, stop))
            try:
                report = await site.attack(
                    "held_connections", port=site.modbus_port, kind="modbus", sources=SOURCES,
                    per_source=32, hold_s=8.0, every_s=3.0,
                )  # fmt: skip
            finally:
                stop.set()
            got = await probe
        site.assert_unharmed(window[0])  # the SCADA's own connection predates the attack
        assert report["opened"] == 64, report
        assert report["alive_at_end"] >= 60, report
        # Seen: {'ok': 1, 'closed': 32}.
        assert set(got) == {"ok"}, got


# -- MQTT: Home Assistant's status -------------------------------------------------------


@pytest.mark.attack_alone
async def test_a_storm_of_home_assistant_births_costs_the_loop_nothing(tmp_path: Path) -> None:
    async with plant(tmp_path) as site:
        async with site.window() as window:
            report = await site.attack(
                "mqtt_flap", port=site.broker.port, topic="homeassistant/status",
                payloads=["online"], count=1000, duration_s=6.0, watch="homeassistant/#",
            )  # fmt: skip
        assert report["sent"] == 1000, report
        assert report["carried"] > report["sent"], report  # the gateway did republish
        site.assert_unharmed(window[0])


# -- OPC UA: anonymous subscriptions -----------------------------------------------------


@pytest.mark.attack_alone
async def test_anonymous_subscriptions_of_500_items_cost_the_loop_little(
    tmp_path: Path, pair: tuple[Path, Path]
) -> None:
    async with plant(tmp_path) as site:
        async with site.window() as window:
            report = await site.attack(
                "opcua_anonymous", url=site.opcua_url, security=site.security(pair),
                namespace="urn:sj300-async:gw1",
                variables=["hall/Drive1/Monitoring/ConverterOutputFrequency"],
                sessions=16, items=500, mode="subscribe", publishing_ms=10, duration_s=8.0,
            )  # fmt: skip
        assert report["sessions"] == 16, report
        # Past the address's share of monitored items the rest are refused (sessions
        # asking at once may each be refused part of theirs: at most the share is held).
        assert 500 <= report["outcomes"].get("items", 0) <= ITEMS_PER_ADDRESS, report
        assert report["notified"] > 0, report
        # Not yet issue 41's bounds for this one (open): the items' fan-out took the
        # loop's p99 to 21 ms in a process of its own but 138 ms (max 250) in a suite's
        # worker. What holds: no lease lost, the poll at its rate, no stall /healthz
        # would call one (0.5 s).
        site.assert_unharmed(window[0], p99_bound_s=0.25, max_bound_s=0.5)
