"""The arbiter's FR-700 duties: the host's ACK and its timing, re-output after a damaged reply."""

from __future__ import annotations

from contextlib import AbstractAsyncContextManager

import pytest

import sj300_async as sj
from sj300_async import bus as sjbus
from sj300_async import wire
from sj300_async.fr700 import Fr700Dialect, Fr700Drive
from sj300_async.simulator.fr700 import Fr700SimulatedBus

ACK = b"\x06"
NAK = b"\x15"


def fr700_bus(
    query: str = "",
    *,
    timeout: float | None = None,
    retries: int = 2,
    trace: sjbus.TraceHook | None = None,
    dialect: Fr700Dialect | None = None,
) -> AbstractAsyncContextManager[sj.Bus[Fr700Drive, None]]:
    return sj.open_bus(
        f"sim://?protocol=fr700&nodes=0-3{query}",
        protocol="fr700",
        timeout=timeout,
        retries=retries,
        trace=trace,
        dialect=dialect,
    )


def sim_of(bus: sj.Bus[Fr700Drive, None]) -> Fr700SimulatedBus:
    assert isinstance(bus.simulator, Fr700SimulatedBus)
    return bus.simulator


async def test_a_damaged_reply_is_asked_for_again_not_retried() -> None:
    trace: list[sjbus.TraceRecord] = []
    async with fr700_bus(trace=trace.append) as bus:
        drive = bus.drive(2)
        await drive.set_frequency(33.0)
        sim_of(bus).faults.corrupt_next(2)
        assert await drive.read_set_frequency() == 33.0
        assert bus.stats.reoutput_requests == 1
        assert bus.stats.bad_frames == 1
        assert bus.stats.transactions.retries == 0
        assert bus.stats.transactions.protocol_errors == 0
        assert sim_of(bus).stats.reoutputs == 1
    sent = [r for r in trace if r.direction == "tx"]
    assert sent[-1].data == NAK + b"02\r"  # format F
    bad = next(r for r in trace if any(isinstance(e, wire.BadFrame) for e in r.events))
    # the host waits its processing delay (10 ms) before answering
    assert sent[-1].timestamp - bad.timestamp >= 0.010 - 1e-4


async def test_a_second_damaged_reply_ends_the_attempt_as_a_protocol_error() -> None:
    async with fr700_bus(timeout=0.1, retries=0) as bus:
        sim_of(bus).faults.corrupt_next(1, count=2)
        with pytest.raises(sj.RemoteProtocolError, match="corrupted"):
            await bus.drive(1).read_status()
        assert bus.stats.reoutput_requests == 1  # once per attempt
    async with fr700_bus(timeout=0.1, retries=1) as bus:
        sim_of(bus).faults.corrupt_next(1, count=2)
        assert not (await bus.drive(1).read_status()).running  # the retry gets it
        assert bus.stats.transactions.retries == 1


async def test_without_reoutput_the_request_is_retried() -> None:
    dialect = Fr700Dialect(request_reoutput=False)
    async with fr700_bus(timeout=0.05, dialect=dialect) as bus:
        sim_of(bus).faults.corrupt_next(1)
        assert not (await bus.drive(1).read_status()).running
        assert bus.stats.reoutput_requests == 0
        assert bus.stats.transactions.retries == 1


async def test_a_damaged_ack_is_not_asked_for_again() -> None:
    async with fr700_bus(timeout=0.05) as bus:
        sim_of(bus).faults.corrupt_next(1)
        await bus.drive(1).stop()  # the ACK was damaged: retried, the stop is idempotent
        assert bus.stats.reoutput_requests == 0
        assert bus.stats.transactions.retries == 1


async def test_the_host_acknowledges_data_and_rests_10_ms() -> None:
    trace: list[sjbus.TraceRecord] = []
    async with fr700_bus("&ack=1", trace=trace.append) as bus:
        drive = bus.drive(3)
        await drive.read_status()
        await drive.read_status()
        await drive.stop()  # a write: its ACK reply is not acknowledged
        await drive.read_status()
    records = [(r.direction, r.data, r.timestamp) for r in trace]
    sent = [r for r in records if r[0] == "tx"]
    assert [s[1][:1] for s in sent] == [b"\x05", ACK, b"\x05", ACK, b"\x05", b"\x05", ACK]
    for i, (direction, data, at) in enumerate(records):
        if direction == "tx" and data[:1] == ACK:
            assert data == ACK + b"03\r"
            reply_at = records[i - 1][2]
            assert at - reply_at >= 0.010 - 1e-4  # the computer's processing delay
            after = next((r for r in records[i + 1 :] if r[0] == "tx"), None)
            if after is not None:
                assert after[2] - at >= 0.010 - 1e-4  # 10 ms after the ACK
    assert sim_of(bus).stats.host_acks >= 2


async def test_a_late_reply_never_answers_the_next_request() -> None:
    async with fr700_bus(timeout=0.05, retries=0) as bus:
        sim = sim_of(bus)
        await bus.drive(1).set_frequency(11.0)
        await bus.drive(2).set_frequency(22.0)
        sim.faults.delay_next(1, 0.08)
        with pytest.raises(sj.ReplyTimeoutError):
            await bus.drive(1).read_set_frequency()
        # drive 1's late reply arrives while the line drains; drive 1 asks again
        assert await bus.drive(1).read_set_frequency() == 11.0
        assert await bus.drive(2).read_set_frequency() == 22.0
        assert bus.stats.drains == 1
