"""Embedding the library in a long-running asyncio service.

A tiny HTTP service (standard library only) that keeps the state of a few
drives up to date in the background and serves it as JSON:

    python examples/service.py [URL] [--port 8080] [--run-for SECONDS]
    curl http://127.0.0.1:8080/          -> {"1": {"output_frequency_hz": ...}, ...}
    curl -X POST http://127.0.0.1:8080/stop

The bus is opened once for the life of the service; the poll loop and the
HTTP handlers share it, and the arbiter serializes their requests. A stop
request from HTTP goes before any queued poll.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import json

import sj300_async as sj


class DriveService:
    def __init__(self, bus: sj.Bus, nodes: list[int]) -> None:
        self.bus = bus
        self.nodes = nodes
        self.state: dict[int, dict[str, object]] = {}

    async def poll_forever(self, interval_s: float = 0.2) -> None:
        while True:
            for node in self.nodes:
                try:
                    monitor = await self.bus.drive(node).read_monitor()
                except sj.SJ300Error as exc:  # a time-out or NAK is data here, not a crash
                    self.state[node] = {"error": str(exc)}
                else:
                    self.state[node] = dataclasses.asdict(monitor)
            await asyncio.sleep(interval_s)

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        request_line = (await reader.readline()).decode(errors="replace").split()
        while (await reader.readline()).strip():
            pass  # skip headers
        if request_line[:2] == ["POST", "/stop"]:
            await self.bus.broadcast.stop()
            body = {"stopped": True}
        else:
            body = {str(k): v for k, v in self.state.items()}
        payload = json.dumps(body).encode()
        writer.write(
            b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n"
            b"Content-Length: %d\r\nConnection: close\r\n\r\n%s" % (len(payload), payload)
        )
        await writer.drain()
        writer.close()


async def main(url: str, port: int, run_for: float | None) -> None:
    async with sj.open_bus(url) as bus:
        service = DriveService(bus, [1, 2, 3])
        for node in service.nodes:
            await bus.drive(node).set_frequency(10.0 * node)
            await bus.drive(node).run_forward()
        server = await asyncio.start_server(service.handle, "127.0.0.1", port)
        print(
            f"serving drive state on http://127.0.0.1:{server.sockets[0].getsockname()[1]}/",
            flush=True,
        )
        poller = asyncio.create_task(service.poll_forever())
        try:
            async with server:
                if run_for is None:
                    await server.serve_forever()
                else:
                    await asyncio.sleep(run_for)
        finally:
            poller.cancel()
            await asyncio.wait([poller])  # does not swallow a cancellation of main()
            await bus.broadcast.stop()


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url", nargs="?", default="sim://?nodes=1-3")
    parser.add_argument("--port", type=int, default=8080)
    parser.add_argument("--run-for", type=float, default=None)
    args = parser.parse_args()
    asyncio.run(main(args.url, args.port, args.run_for))
