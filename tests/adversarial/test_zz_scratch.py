from __future__ import annotations

import asyncio
import contextlib
import logging
import struct
from pathlib import Path
from typing import Any

import pytest

from .plant import OPERATOR_IP, Plant, client_pair, plant
from .test_adversarial import _metrics, _while_healthz

pytestmark = pytest.mark.timeout(240)


def show(name: str, site: Plant, w: Any, report: Any, extra: Any = None) -> None:
    print(f"\n### {name}: p99 {w.p99_s*1000:.1f} ms max {w.max_s*1000:.1f} ms lapses {w.lapses} "
          f"rate {w.samples_per_s:.2f}/{site.idle_rate:.2f} motor {w.motor_running} lease {site.gateway.drives[0].lease.holder}\n  report {report}\n  extra {extra}")


async def _modbus_probe(site: Plant, stop: asyncio.Event) -> dict[str, int]:
    got: dict[str, int] = {}
    while not stop.is_set():
        try:
            r, w = await asyncio.open_connection("127.0.0.1", site.modbus_port, local_addr=(OPERATOR_IP, 0))
            w.write(struct.pack(">HHHBBHH", 7, 0, 6, 1, 3, 0, 1))
            data = await asyncio.wait_for(r.read(100), 2)
            key = "ok" if data else "closed"
            w.close()
        except Exception as exc:
            key = type(exc).__name__
        got[key] = got.get(key, 0) + 1
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), 0.25)
    return got


@pytest.mark.parametrize("kind", ["http", "modbus"])
async def test_held(tmp_path: Path, kind: str) -> None:
    async with plant(tmp_path) as site:
        port = site.http_port if kind == "http" else site.modbus_port
        attack = site.attack("held_connections", port=port, kind=kind, sources=["127.0.0.10", "127.0.0.11"], per_source=32, hold_s=8, every_s=3)
        async with site.window() as window:
            if kind == "http":
                report, health = await _while_healthz(site, attack)
            else:
                stop = asyncio.Event()
                probe = asyncio.create_task(_modbus_probe(site, stop))
                try:
                    report = await attack
                finally:
                    stop.set()
                health = await probe
        show(kind + " held", site, window[0], report, health)


async def test_pipeline(tmp_path: Path) -> None:
    async with plant(tmp_path) as site:
        async with site.window() as window:
            report = await site.attack("http_pipeline", port=site.http_port, path="/metrics", count=200, duration_s=6)
        show("pipeline metrics", site, window[0], report)


async def test_pipeline_static(tmp_path: Path) -> None:
    async with plant(tmp_path) as site:
        async with site.window() as window:
            report = await site.attack("http_pipeline", port=site.http_port, path="/", count=200, duration_s=6)
        show("pipeline /", site, window[0], report)


async def test_modbus_reads(tmp_path: Path) -> None:
    async with plant(tmp_path) as site:
        async with site.window() as window:
            report = await site.attack("modbus_reads", port=site.modbus_port, duration_s=6)
        show("modbus reads", site, window[0], report)


async def test_ha_flap(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    async with plant(tmp_path) as site:
        async with site.window() as window:
            report = await site.attack("mqtt_flap", port=site.broker.port, topic="homeassistant/status", count=3000, duration_s=6, watch="homeassistant/#")
        lines = sum(1 for r in caplog.records if "Home Assistant is online" in r.getMessage())
        show("ha flap", site, window[0], report, {"log_lines": lines, "records": len(caplog.records)})


@pytest.mark.parametrize("mode", ["subscribe", "read"])
async def test_opcua_anon(tmp_path: Path, mode: str) -> None:
    pair = client_pair(tmp_path)
    async with plant(tmp_path) as site:
        async with site.window() as window:
            report = await site.attack("opcua_anonymous", url=site.opcua_url, security=site.security(pair), namespace="urn:sj300-async:gw1",
                                       variables=["hall/Drive1/Monitoring/ConverterOutputFrequency"], sessions=4, items=500, mode=mode, duration_s=6)
        show("opcua " + mode, site, window[0], report)
