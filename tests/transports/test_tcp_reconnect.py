"""The TCP bridge recovers when the device server goes away and comes back."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from cli.clirun import closed_port
from waiting import wait_for

import sj300_async as sj
from sj300_async.simulator import serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus

FAST = sj.ReconnectPolicy(initial_s=0.02, max_s=0.1, connect_timeout_s=1.0)


async def test_requests_fail_promptly_while_down_and_work_after_restart() -> None:
    sim = SimulatedBus(nodes=[1])
    server = await serve_tcp(sim)
    port = server.port
    async with sj.open_bus(f"tcp://127.0.0.1:{port}", timeout=0.3, reconnect=FAST) as bus:
        drive = bus.drive(1)
        assert (await drive.read_status()).b is sj.StatusB.STOPPED
        for cycle in range(3):
            server.close()
            await server.wait_closed()
            loop = asyncio.get_running_loop()
            # While the server is down every request fails fast and typed.
            for _ in range(5):
                start = loop.time()
                with pytest.raises((sj.TransportError, sj.ReplyTimeoutError)):
                    await drive.read_status()
                assert loop.time() - start < 0.35
            server = await serve_tcp(sim, port=port)
            for _ in range(100):
                if bus.connected:
                    break
                await asyncio.sleep(0.02)
            assert bus.connected, f"no reconnect in cycle {cycle}"
            assert (await drive.read_status()).b is sj.StatusB.STOPPED
        assert bus.stats.connects == 4
        assert bus.stats.disconnects == 3
    server.close()
    await server.wait_closed()


async def test_unreachable_bridge_fails_at_open() -> None:
    sim = SimulatedBus(nodes=[1])
    server = await serve_tcp(sim)
    port = server.port
    server.close()
    await server.wait_closed()
    with pytest.raises(sj.TransportError, match="could not connect") as info:
        async with sj.open_bus(f"tcp://127.0.0.1:{port}"):
            pass
    assert isinstance(info.value, ConnectionError)


async def test_a_bridge_down_at_open_connects_later_in_the_background() -> None:
    sim = SimulatedBus(nodes=[1])
    port = closed_port()
    url = f"tcp://127.0.0.1:{port}"
    async with sj.open_bus(url, timeout=0.3, reconnect=FAST, connect="background") as bus:
        assert not bus.connected
        assert isinstance(bus.link.last_error, ConnectionRefusedError)
        # Served as a link lost later: every request fails at once, typed.
        with pytest.raises(sj.TransportError, match=r"not connected: .*Connect call failed"):
            await bus.drive(1).read_status()
        server = await serve_tcp(sim, port=port)
        async with server:
            await wait_for(lambda: bus.connected, "the background reconnect")
            assert bus.link.last_error is None
            assert (await bus.drive(1).read_status()).b is sj.StatusB.STOPPED
            assert (bus.stats.connects, bus.stats.disconnects) == (1, 0)


async def test_a_missing_serial_device_is_a_line_down_in_the_background(tmp_path: Path) -> None:
    url = f"serial://{tmp_path}/ttyUSB9?baudrate=19200"  # a USB adapter not plugged in
    with pytest.raises(sj.TransportError, match="cannot open serial port"):
        async with sj.open_bus(url):
            pass
    async with sj.open_bus(url, reconnect=FAST, connect="background") as bus:
        assert not bus.connected
        assert "cannot open serial port" in str(bus.link.last_error)


async def test_connect_takes_one_of_two_modes() -> None:
    with pytest.raises(sj.LocalProtocolError, match='connect must be "now" or "background"'):
        async with sj.open_bus("sim://?nodes=1", connect="later"):  # type: ignore[call-overload]
            pass
