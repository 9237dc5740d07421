"""A short reliability soak for FR-700: a noisy line, many tasks, every request accounted for.

Bytes are corrupted, dropped, inserted and fragmented in both directions
(the loopback transport's :class:`~sj300_async.transports.LineFaults`,
seeded so a failure can be replayed). Every request must end with the right
value or a typed :class:`~sj300_async.SJ300Error` — never a wrong value,
never another exception, never a hang — and once the noise stops every
drive reads back exactly what the simulator holds.

A value read back may be one whose write *failed* as far as the host knows:
the drive may have executed a write whose ACK was lost. So a read must
return the last confirmed value or one attempted since.
"""

from __future__ import annotations

import asyncio
import random

import pytest

import sj300_async as sj
from sj300_async.simulator.fr700 import Fr700SimulatedBus
from sj300_async.transports import LineFaults

STATIONS = (0, 1, 2, 3)
OPERATIONS = 60


def noisy(seed: int) -> LineFaults:
    return LineFaults(
        rng=random.Random(seed),
        corrupt_rate=0.004,
        drop_rate=0.002,
        insert_rate=0.002,
        fragment_max=4,
    )


@pytest.mark.parametrize("query", ["", "&terminator=none&ack=1"])
async def test_every_request_ends_with_the_right_value_or_a_typed_error(query: str) -> None:
    to_drive, to_host = noisy(8), noisy(9)
    errors: dict[str, int] = {}
    async with sj.open_bus(
        f"sim://?protocol=fr700&nodes=0-3{query}",
        protocol="fr700",
        timeout=0.04,
        retries=2,
        faults=(to_drive, to_host),
    ) as bus:
        sim = bus.simulator
        assert isinstance(sim, Fr700SimulatedBus)

        async def worker(station: int) -> None:
            drive = bus.drive(station)
            rng = random.Random(station)
            confirmed: float | None = None
            attempted: set[float] = set()
            for _ in range(OPERATIONS):
                try:
                    if rng.random() < 0.5:
                        hz = rng.randrange(0, 12000) / 100
                        attempted.add(hz)
                        await drive.set_frequency(hz)
                        confirmed, attempted = hz, set()
                    else:
                        value = await drive.read_set_frequency()
                        allowed = attempted | ({confirmed} if confirmed is not None else {0.0})
                        assert value in allowed, (station, value, confirmed, attempted)
                except sj.SJ300Error as exc:
                    errors[type(exc).__name__] = errors.get(type(exc).__name__, 0) + 1

        async with asyncio.timeout(60):
            await asyncio.gather(*(worker(s) for s in STATIONS))

        # The noise stops: every drive now reads back exactly what it holds.
        for faults in (to_drive, to_host):
            faults.corrupt_rate = faults.drop_rate = faults.insert_rate = 0.0
        for station in STATIONS:
            expected = sim.drives[station].set_frequency_hz
            assert await bus.drive(station).read_set_frequency() == expected
        injected = to_drive.counts.total() + to_host.counts.total()
        assert injected > 0
        totals = bus.stats.transactions
        # the noise was felt and survived: retries, re-outputs or typed failures
        assert totals.retries + bus.stats.reoutput_requests + sum(errors.values()) > 0
        assert set(errors) <= {"ReplyTimeoutError", "RemoteProtocolError", "NakError"}
