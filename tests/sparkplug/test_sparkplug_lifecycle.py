"""The edge node's session as a Sparkplug host sees it: mosquitto delivers, Eclipse Tahu decodes.

Births, data by exception, device deaths and rebirths, the node's death
after ``kill -9``, and the sequence number's wrap. Every check reads what
the broker delivered to an independent subscriber (host.py), decoded by
Tahu's codec, not what the edge node says it sent.
"""

from __future__ import annotations

import asyncio
import contextlib
import sys
import time
from pathlib import Path
from typing import Any

from cli.clirun import cli_env
from mqtt_broker import Broker

from sj300_async.gateway import Heartbeat, ParameterWrite, RunCommand, SetFrequency
from sj300_async.simulator import LinePacing, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus
from sj300_async.wire import Direction

from .conftest import SimLine, drive, edge, running_gateway, spb_toml
from .host import Codec, Host, SpbMessage, host

DEVICES = ("hall-1", "hall-2", "hall-3", "hall-4")
REBIRTH = "Node Control/Rebirth"


def births(h: Host, device: str) -> list[SpbMessage]:
    return h.of("DBIRTH", device)


def names(message: SpbMessage) -> dict[str, Any]:
    """A birth's metrics by name."""
    return {m["name"]: m for m in message.payload["metrics"]}


def current(h: Host, device: str) -> dict[str, Any]:
    """The device's values as a host holds them: its last birth, then each DDATA by alias."""
    birth = births(h, device)[-1]
    by_alias = {m["alias"]: m["name"] for m in birth.payload["metrics"]}
    values = {m["name"]: m["value"] for m in birth.payload["metrics"]}
    after = h.messages.index(birth)
    for message in h.messages[after + 1 :]:
        if message.kind == "DDATA" and message.device == device:
            for metric in message.payload["metrics"]:
                values[by_alias[metric["alias"]]] = metric["value"]
    return values


def seqs_follow(messages: list[SpbMessage]) -> None:
    """Each message after an NBIRTH (seq 0) is one more, modulo 256 (NDEATH has none)."""
    expected = None
    for message in messages:
        if message.kind in ("NCMD", "DCMD"):  # the host's own
            continue
        if message.kind == "NDEATH":
            assert message.seq is None, message
            continue
        if message.kind == "NBIRTH":
            assert message.seq == 0, message
        else:
            assert message.seq == expected, (message.kind, message.device, message.seq, expected)
        expected = (message.seq + 1) % 256  # type: ignore[operator]


async def test_nbirth_then_a_dbirth_per_drive_then_ddata_by_exception(
    sim_line: SimLine, broker: Broker, tahu: Codec
) -> None:
    started = time.time() * 1000
    async with host(broker, tahu) as h:
        async with running_gateway(spb_toml(sim_line.url, broker)) as gateway:
            await h.until(lambda m: m.kind == "DBIRTH", "a birth per drive", count=4)
            one = drive(gateway, 1)
            for request in (Heartbeat(), SetFrequency(20.0), RunCommand(Direction.FORWARD)):
                assert (await gateway.write("test", one, request)).ok
            await h.until(
                lambda m: m.kind == "DDATA" and current(h, "hall-1").get("Running") is True,
                "the run in a DDATA",
            )
            samples = edge(gateway).stats.samples
        ended = time.time() * 1000
        await h.until(lambda m: m.kind == "NDEATH", "the clean stop's NDEATH")
    nbirth = h.messages[0]
    assert nbirth.kind == "NBIRTH"
    assert nbirth.topic == "spBv1.0/plant/NBIRTH/gw1"
    node = names(nbirth)
    assert node["bdSeq"]["type"] == "Int64"
    assert node["bdSeq"]["value"] == 0
    assert node[REBIRTH] == {"name": REBIRTH, "type": "Boolean", "value": False,
                             "timestamp": nbirth.payload["timestamp"]}  # fmt: skip
    assert "alias" not in node["bdSeq"]
    assert node["Lines/hall/Connected"]["type"] == "Boolean"
    assert sorted(str(m.device) for m in h.of("DBIRTH")) == list(DEVICES)
    aliases = [m["alias"] for m in nbirth.payload["metrics"] if "alias" in m]
    for birth in h.of("DBIRTH"):
        metrics = birth.payload["metrics"]
        assert all({"name", "alias", "type", "timestamp"} <= set(m) for m in metrics)
        assert {m["timestamp"] for m in metrics} == {birth.payload["timestamp"]}
        assert started <= birth.payload["timestamp"] <= ended
        aliases += [m["alias"] for m in metrics]
    assert len(aliases) == len(set(aliases)), "aliases are unique across the edge node"
    first = names(births(h, "hall-1")[0])
    assert first["Output Frequency"]["properties"]["engUnit"] == {"type": "String", "value": "Hz"}
    a004 = first["Parameters/A004"]
    assert a004["properties"]["engUnit"]["value"] == "Hz"
    assert a004["properties"]["engHigh"]["value"] > a004["properties"]["engLow"]["value"]
    assert {"Control/Lease", "Control/Stop", "Control/Last Refusal"} <= set(first)
    assert not {"Control/Lease", "Control/Stop"} & set(names(births(h, "hall-3")[0]))
    assert first["Info/Node"] == {**first["Info/Node"], "type": "UInt32", "value": 1}
    data = h.of("DDATA")
    assert data, "the run changed values"
    for message in data:
        assert all("name" not in m and "alias" in m for m in message.payload["metrics"])
        assert {m["timestamp"] for m in message.payload["metrics"]} == {
            message.payload["timestamp"]
        }
    # Report by exception: no DDATA repeats a value the host already holds.
    held: dict[tuple[str | None, int], Any] = {}
    for message in h.messages:
        for metric in message.payload.get("metrics", []):
            key = (message.device, metric["alias"]) if "alias" in metric else None
            if key is None:
                continue
            if message.kind == "DDATA":
                assert held[key] != metric["value"], (message.device, metric)
            held[key] = metric["value"]
    assert len(data) + 4 < samples, "samples that changed nothing sent nothing"
    final = current(h, "hall-1")
    assert (final["Frequency Command"], final["Direction"]) == (20.0, "forward")
    seqs_follow(h.messages)
    assert h.messages[-1].kind == "NDEATH"  # a clean stop says so itself
    assert names(h.messages[-1]) == {"bdSeq": {**names(h.messages[-1])["bdSeq"], "value": 0}}


async def test_a_rebirth_on_ncmd_sends_every_birth_again_with_the_same_bdseq(
    sim_line: SimLine, broker: Broker, tahu: Codec
) -> None:
    async with host(broker, tahu) as h, running_gateway(spb_toml(sim_line.url, broker)) as gw:
        await h.until(lambda m: m.kind == "DBIRTH", "a birth per drive", count=4)
        await h.command("NCMD", [{"name": REBIRTH, "type": "Boolean", "value": True}])
        await h.until(lambda m: m.kind == "DBIRTH", "the births again", count=8)
        assert edge(gw).stats.rebirths == 1
    nbirths = h.of("NBIRTH")
    assert len(nbirths) == 2
    assert [names(m)["bdSeq"]["value"] for m in nbirths] == [0, 0]
    again = h.messages.index(nbirths[1])
    assert sorted(str(m.device) for m in h.messages[again + 1 : again + 5]) == list(DEVICES)
    seqs_follow(h.messages)


async def test_a_silent_drive_dies_and_is_born_again_when_it_answers(
    sim_line: SimLine, broker: Broker, tahu: Codec
) -> None:
    async with host(broker, tahu) as h, running_gateway(spb_toml(sim_line.url, broker)) as gw:
        await h.until(lambda m: m.kind == "DBIRTH", "a birth per drive", count=4)
        sim_line.sim.faults.silence(3)
        await h.until(lambda m: m.kind == "DDEATH", "the drive's death")
        assert not drive(gw, 3).snapshot.online
        sim_line.sim.faults.silence(3, False)
        await h.until(lambda m: m.kind == "DBIRTH" and m.device == "hall-3", "its birth", count=2)
    (death,) = h.of("DDEATH")
    assert death.device == "hall-3"
    assert death.payload.get("metrics", []) == []
    reborn = births(h, "hall-3")[1]
    assert h.messages.index(reborn) > h.messages.index(death)
    assert names(reborn)["Output Frequency"]["value"] == 0.0  # every value again
    seqs_follow(h.messages)


async def test_the_ndeath_with_the_births_bdseq_follows_a_kill_9(
    broker: Broker, tahu: Codec, tmp_path: Path
) -> None:
    config = tmp_path / "gateway.toml"
    config.write_text(
        spb_toml("sim://?nodes=1-4", broker).replace('nodes = "1-4"', 'nodes = "1-2"'),
        encoding="utf-8",
    )
    async with host(broker, tahu) as h:
        proc = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "sj300_async", "gateway", "--config", str(config),
            stdin=asyncio.subprocess.DEVNULL, stdout=asyncio.subprocess.DEVNULL,
            stderr=asyncio.subprocess.DEVNULL, env=cli_env(),
        )  # fmt: skip
        try:
            await h.until(lambda m: m.kind == "DBIRTH", "the births", count=2, timeout=20)
            proc.kill()
            await h.until(lambda m: m.kind == "NDEATH", "the will")
        finally:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            await proc.wait()
    (nbirth,) = h.of("NBIRTH")
    (ndeath,) = h.of("NDEATH")
    assert names(ndeath)["bdSeq"]["value"] == names(nbirth)["bdSeq"]["value"] == 0
    assert list(names(ndeath)) == ["bdSeq"]
    assert ndeath.seq is None
    assert not ndeath.retained


async def test_the_sequence_number_wraps_from_255_to_0(broker: Broker, tahu: Codec) -> None:
    # Four drives on a 115200-baud line, each ramping slowly: every poll changes its
    # output frequency, so every sample is a DDATA.
    sim = SimulatedBus(range(1, 5))
    async with await serve_tcp(sim, pacing=LinePacing(115200, 8, "N", 1)) as server:
        url = f"tcp://127.0.0.1:{server.port}?baudrate=115200"  # the line's pace alike
        text = spb_toml(url, broker, interval_s=0.05)
        text = text.replace('nodes = "1-2"', 'nodes = "1-4"')  # control of every drive
        text = text.replace('["A004", "F002"]', '["F002"]')  # fewer reads: faster polls
        async with host(broker, tahu) as h, running_gateway(text) as gateway:
            await h.until(lambda m: m.kind == "DBIRTH", "a birth per drive", count=4)
            for one in gateway.drives:
                accel = one.profile.parameters.spec("F002")
                for request in (
                    Heartbeat(),
                    ParameterWrite("F002", round(60 * accel.scale)),
                    SetFrequency(50.0),
                    RunCommand(Direction.FORWARD),
                ):
                    assert (await gateway.write("test", one, request)).ok
            await h.until(lambda m: m.seq == 255, "seq 255", timeout=60)
            await h.until(lambda m: m.kind != "NBIRTH" and m.seq == 0, "seq 0 again")
    assert len(h.of("NBIRTH")) == 1, "one session: the wrap is no rebirth"
    seqs_follow(h.messages)
    wrapped = [i for i, m in enumerate(h.messages) if m.seq == 255]
    assert h.messages[wrapped[0] + 1].seq == 0
