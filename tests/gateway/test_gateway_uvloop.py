"""The gateway on uvloop, with its socket northbounds: Modbus TCP, HTTP and MQTT.

The library is embedded in services that run uvloop, whose transports implement
asyncio's interface without deriving from its classes: a ``connection_made`` that
asserted ``isinstance(transport, asyncio.Transport)`` refused every connection
there (the Modbus and HTTP servers, the MQTT client). This test runs a gateway on a
uvloop loop, against a real mosquitto, and checks that each northbound answers: a
Modbus read of a drive's registers, an HTTP GET of ``/healthz``, and the drive's
MQTT state delivered to a subscriber (the gateway's own client, on the same loop).
"""

from __future__ import annotations

import asyncio
import struct
import textwrap
from pathlib import Path

import uvloop
from mqtt_broker import running_broker

from sj300_async.gateway.mqtt import StateMessage, Topics
from sj300_async.gateway.mqttlink.client import Client

from .conftest import metrics_port, modbus_port, polled, running_gateway

TIMEOUT_S = 5.0


def test_the_gateway_serves_modbus_http_and_mqtt_on_uvloop(tmp_path: Path) -> None:
    with asyncio.Runner(loop_factory=uvloop.new_event_loop) as runner:
        runner.run(_serve_on_uvloop(tmp_path))


async def _serve_on_uvloop(tmp_path: Path) -> None:
    assert type(asyncio.get_running_loop()).__module__.startswith("uvloop")
    async with running_broker(tmp_path) as broker:
        text = textwrap.dedent(
            f"""
            [gateway]
            id = "uv"
            [modbus]
            listen = "127.0.0.1:0"
            [http]
            listen = "127.0.0.1:0"
            [mqtt]
            url = "{broker.url}"
            [[lines]]
            name = "hall"
            url = "sim://?nodes=1-2"
            nodes = "1-2"
            interval_s = 0.05
            """
        )
        async with running_gateway(text) as gateway:
            await polled(gateway)
            # Modbus: function 3, registers 0..3 of unit 1 (online, fresh, SJ300, node 1).
            reply = await _exchange(
                modbus_port(gateway), struct.pack(">HHHBBHH", 7, 0, 6, 1, 3, 0, 4)
            )
            assert reply[:9] == struct.pack(">HHHBBB", 7, 0, 11, 1, 3, 8), reply.hex(" ")
            assert struct.unpack(">4H", reply[9:]) == (1, 0, 1, 1)
            # HTTP: the health check.
            request = b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n"
            answer = await _exchange(metrics_port(gateway), request, whole=True)
            head, _, body = answer.partition(b"\r\n\r\n")
            assert (head.split()[1], body) == (b"200", b"ok\n"), answer
            # MQTT: the drive's state, published by the gateway, read by a subscriber.
            topic = Topics("uv").state("hall", 1)
            watcher = Client("127.0.0.1", broker.port, identifier="watcher", connect_timeout_s=5)
            async with watcher:
                await watcher.subscribe(topic)
                async with asyncio.timeout(TIMEOUT_S):
                    message = await anext(watcher.messages)
            assert message.topic == topic
            state = StateMessage.from_json(message.payload)
            assert (state.gateway, state.line, state.node, state.online) == ("uv", "hall", 1, True)


async def _exchange(port: int, request: bytes, *, whole: bool = False) -> bytes:
    """Send *request*; the answer: a Modbus TCP frame, or (*whole*) all until the close."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(request)
        async with asyncio.timeout(TIMEOUT_S):
            if whole:
                return await reader.read()
            header = await reader.readexactly(6)
            return header + await reader.readexactly(struct.unpack(">H", header[4:])[0])
    finally:
        writer.close()
        await writer.wait_closed()
