"""Random frames against the running Modbus server: no traceback, and a normal client served.

10,000 frames in the default suite (``--soak``: 100,000), seeded
(``--soak-seed``). Three kinds, each checked for what the server must do:

- a well-framed request with a random unit, function and data (80 %),
  followed on the same connection by a probe read: exactly one answer
  each, in order, with their own transaction and unit ids;
- a broken header (protocol id other than 0, or an impossible length)
  with random bytes after it (10 %): the connection is closed, unanswered;
- random bytes on a connection of their own, then the client's end of
  the stream (10 %): whatever answers come are well framed, and the
  server closes.

Between batches a normal client (pymodbus's) reads every drive and checks
the values. The gateway is read-only: no random write reaches a drive.
"""

from __future__ import annotations

import asyncio
import logging
import random
import struct
from typing import Any

import pytest
from pymodbus.client import AsyncModbusTcpClient

from .conftest import SimLine, gateway_toml, modbus_client, polled, running_gateway
from .test_gateway_modbus_wire import answer, server_of

FRAMES = 10_000
SOAK_FRAMES = 100_000
#: Units with a drive (1..4), the summary (255) and some without.
UNITS = (0, 1, 2, 3, 4, 5, 99, 255)


def _probe(tid: int, unit: int) -> bytes:
    return struct.pack(">HHHBBHH", tid, 0, 6, unit, 3, 3, 1)  # register 3: the node


def _framed(rng: random.Random, tid: int) -> tuple[bytes, int]:
    unit = rng.choice(UNITS)
    function = rng.choice((3, 4, 6, 16, 23, rng.randrange(256)))
    if function in (3, 4, 6) and rng.random() < 0.7:
        data = struct.pack(">HH", rng.randrange(0x10000), rng.choice((0, 1, 2, 125, 126, 0xFFFF)))
    elif function == 16 and rng.random() < 0.7:
        count = rng.randrange(130)
        byte_count = 2 * count if rng.random() < 0.8 else rng.randrange(256)
        data = struct.pack(">HHB", rng.randrange(0x10000), count, byte_count % 256)
        data += rng.randbytes(min(2 * count, 247))
    else:
        data = rng.randbytes(rng.randrange(253))
    pdu = bytes([function]) + data
    return struct.pack(">HHHB", tid, 0, 1 + len(pdu), unit) + pdu, unit


def _broken(rng: random.Random) -> bytes:
    if rng.random() < 0.5:
        header = struct.pack(">HHHB", rng.randrange(0x10000), rng.randrange(1, 0x10000), 6, 1)
    else:
        length = rng.choice((0, 1, *range(255, 300), rng.randrange(255, 0x10000)))
        header = struct.pack(">HHHB", rng.randrange(0x10000), 0, length, 1)
    return header + rng.randbytes(rng.randrange(20))


def _framed_answers(data: bytes) -> None:
    """*data* (what came before the close) holds whole, well-formed answers only."""
    while data:
        _tid, protocol, length = struct.unpack_from(">HHH", data)
        assert protocol == 0, data.hex(" ")
        assert 3 <= length <= 254, data.hex(" ")
        data = data[6 + length :]


class _Fuzzer:
    def __init__(self, port: int, rng: random.Random) -> None:
        self.port = port
        self.rng = rng
        self.stream: tuple[asyncio.StreamReader, asyncio.StreamWriter] | None = None
        self.tid = 0
        self.counts = {"framed": 0, "broken": 0, "garbage": 0, "reconnects": 0}

    async def _connection(self) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        if self.stream is None:
            self.stream = await asyncio.open_connection("127.0.0.1", self.port)
            self.counts["reconnects"] += 1
        return self.stream

    async def _drop(self) -> None:
        if self.stream is not None:
            self.stream[1].close()
            self.stream = None

    async def one(self) -> None:
        kind = self.rng.random()
        self.tid = (self.tid + 2) % 0x10000
        if kind < 0.8:
            await self._framed()
        elif kind < 0.9:
            await self._broken()
        else:
            await self._garbage()

    async def _framed(self) -> None:
        self.counts["framed"] += 1
        reader, writer = await self._connection()
        frame, unit = _framed(self.rng, self.tid)
        writer.write(frame + _probe(self.tid + 1, 1))
        first, probe = await answer(reader), await answer(reader)
        assert struct.unpack_from(">HHHB", first)[::3] == (self.tid, unit), first.hex(" ")
        assert probe == struct.pack(">HHHBBBH", self.tid + 1, 0, 5, 1, 3, 2, 1), probe.hex(" ")

    async def _broken(self) -> None:
        self.counts["broken"] += 1
        reader, writer = await self._connection()
        writer.write(_broken(self.rng))
        async with asyncio.timeout(5):
            assert await reader.read() == b""  # closed, unanswered
        await self._drop()

    async def _garbage(self) -> None:
        self.counts["garbage"] += 1
        await self._drop()
        reader, writer = await asyncio.open_connection("127.0.0.1", self.port)
        writer.write(self.rng.randbytes(self.rng.randrange(1, 64)))
        writer.write_eof()
        async with asyncio.timeout(5):
            _framed_answers(await reader.read())
        writer.close()


async def _normal_reads(client: AsyncModbusTcpClient) -> None:
    for unit in (1, 2, 3, 4):
        response = await client.read_holding_registers(2, count=2, device_id=unit)
        assert not response.isError(), response
        assert response.registers == [1, unit]


async def test_random_frames_never_log_a_traceback_and_a_normal_client_is_served(
    sim_line: SimLine,
    caplog: pytest.LogCaptureFixture,
    soak: bool,
    soak_seed: int,
    soak_figures: dict[str, Any],
) -> None:
    caplog.set_level(logging.DEBUG)
    frames = SOAK_FRAMES if soak else FRAMES
    rng = random.Random(soak_seed)
    async with running_gateway(gateway_toml(sim_line.url)) as gateway:
        await polled(gateway)
        server = server_of(gateway)
        fuzzer = _Fuzzer(server.port, rng)
        normal_reads = 0
        async with modbus_client(gateway) as client:
            for i in range(frames):
                await fuzzer.one()
                if i % 100 == 0:
                    await _normal_reads(client)
                    normal_reads += 4
            await _normal_reads(client)
        await fuzzer._drop()
        bad_frames = server.bad_frames
    tracebacks = [r for r in caplog.records if r.exc_info is not None or r.exc_text]
    assert tracebacks == []
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert "Traceback" not in caplog.text
    assert bad_frames >= fuzzer.counts["broken"]
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) <= 5, [r.getMessage() for r in warnings]  # rate-limited
    soak_figures["modbus_fuzz"] = {
        "frames": frames,
        "seed": soak_seed,
        **fuzzer.counts,
        "bad_frames": bad_frames,
        "normal_reads": normal_reads,
        "tracebacks": len(tracebacks),
        "log_records": len(caplog.records),
    }
