"""A third protocol is one package plus one registry entry: the toy protocol of tests/toyproto.

(tests/ is on sys.path when pytest runs, as for the other helper modules, so
the package imports as ``toyproto``.)

Everything here runs through the library's own stack (open_bus, the URL
parser, the registry, the arbiter over the loopback, sim://, the poller),
and nothing in sj300_async names the toy protocol.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from toyproto import ToyDrive, ToySimulatedBus

import sj300_async as sj
import sj300_async.bus as sjbus
from sj300_async.bus import protocol_names, register_protocol, unregister_protocol


@pytest.fixture(autouse=True)
def toy_registered() -> Iterator[None]:
    register_protocol("toy", "toyproto:TOY_DIALECT")
    yield
    unregister_protocol("toy")


def test_the_library_never_names_the_toy_protocol() -> None:
    package = Path(sj.__file__).parent
    for path in package.rglob("*.py"):
        assert "toy" not in path.read_text().lower(), path


def test_registering_is_checked() -> None:
    assert "toy" in protocol_names()
    with pytest.raises(sj.LocalProtocolError, match="already registered"):
        register_protocol("toy", "toyproto:TOY_DIALECT")
    with pytest.raises(sj.LocalProtocolError, match="lower-case"):
        register_protocol("Toy!", "toyproto:TOY_DIALECT")


async def test_reads_writes_and_refusals_over_sim() -> None:
    # The neutral open_bus takes the protocol from the URL alone (a Bus[Any, Any]).
    async with sjbus.open_bus("sim://?protocol=toy&nodes=1-2", timeout=0.05, retries=0) as bus:
        drive = bus.drive(2)
        assert isinstance(drive, ToyDrive)
        assert bus.description == "sim://(units 1-2)"
        assert await drive.read("speed") == 0
        await drive.write("set", 42)
        assert await drive.read("speed") == 42
        with pytest.raises(sj.NakError) as refused:
            await drive.read("nothing")
        assert (refused.value.node, refused.value.code) == (2, 2)
        with pytest.raises(sj.ReplyTimeoutError):
            await bus.drive(5).read("speed")  # no unit 5 on the line
        with pytest.raises(sj.LocalProtocolError, match="toy protocol has no broadcast"):
            _ = bus.broadcast
        assert bus.stats.transactions.naks[2] == 1
        assert bus.stats.transactions.timeouts == 1


async def test_url_options_node_range_and_read_only() -> None:
    async with sj.open_bus("sim://?protocol=toy&upper=1", protocol="toy", read_only=True) as bus:
        sim = bus.simulator
        assert isinstance(sim, ToySimulatedBus)
        assert sorted(sim.registers) == [1, 2, 3]  # the dialect's default nodes
        assert await bus.drive(1).read("speed") == 0
        assert sim.received[-1] == b"?01 R SPEED"  # upper=1 reached the dialect
        with pytest.raises(sj.ReadOnlyError):
            await bus.drive(1).write("set", 1)
        assert len(sim.received) == 1  # the refused write never reached the line
    with pytest.raises(sj.LocalProtocolError, match=r"units are 1\.\.9"):
        async with sj.open_bus("sim://?protocol=toy&nodes=10", protocol="toy"):
            pass
    # The user's open_bus is typed for SJ300 drives without protocol=: the URL must agree.
    with pytest.raises(sj.LocalProtocolError, match="pass protocol='toy'"):
        async with sj.open_bus("sim://?protocol=toy"):
            pass
    with pytest.raises(sj.LocalProtocolError, match="options of protocol toy"):
        async with sj.open_bus("sim://?upper=1"):
            pass


async def test_the_poller_polls_it() -> None:
    async with sj.open_bus("sim://?protocol=toy&nodes=1", protocol="toy") as bus:
        await bus.drive(1).write("set", 7)
        poller = sj.Poller(interval_s=0.01, parameters=["toy:set", "F002"])
        poller.add(bus, [1])
        async with poller:
            async for sample in poller.samples():
                assert sample.online, sample.error
                # Sample's types name the built-in protocols' payloads; a toy's are ints.
                status: object = sample.status
                monitor: object = sample.monitor
                assert (status, monitor) == (7, 7)
                assert sample.parameters == {"toy:set": 7.0}  # F002 is SJ300's, not read
                break
