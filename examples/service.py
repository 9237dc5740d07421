"""Embedding the library in a long-running asyncio service.

A tiny HTTP service (standard library only) that keeps the state of a few
drives up to date in the background and serves it as JSON:

    .venv/bin/python examples/service.py [URL] [--port 8080] [--run-for SECONDS]
    curl http://127.0.0.1:8080/       -> {"1": {"output_frequency_hz": 10.0, "direction": "FORWARD",
                                                ...}, ...}
    curl -X POST http://127.0.0.1:8080/stop

Any other path answers 404 (a known path with the wrong method, 405). The
JSON is written the way the ``sj300`` command writes it: an enumeration as
its member's name, a bit field (terminals) as its integer value.

The bus is opened once for the life of the service; the poll loop and the
HTTP handlers share it, and the arbiter serializes their requests. A stop
request from HTTP goes before any queued poll. Ctrl-C stops every drive and
exits with status 130, without a traceback.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import enum
import json
import sys

import sj300_async as sj

ROUTES = {"/": "GET", "/stop": "POST"}  # path -> the method it answers


def jsonable(value: object) -> object:
    """*value* as JSON data: a result dataclass as an object, an enumeration by name."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, enum.Flag):  # terminals: the bits as one integer
        return value.value
    if isinstance(value, enum.Enum):  # "FORWARD", not 1
        return value.name
    return value


class DriveService:
    def __init__(self, bus: sj.Bus, nodes: list[int]) -> None:
        self.bus = bus
        self.nodes = nodes
        self.state: dict[int, object] = {}

    async def poll_forever(self, interval_s: float = 0.2) -> None:
        while True:
            for node in self.nodes:
                try:
                    monitor = await self.bus.drive(node).read_monitor()
                except sj.SJ300Error as exc:  # a time-out or NAK is data here, not a crash
                    self.state[node] = {"error": str(exc)}
                else:
                    self.state[node] = jsonable(monitor)
            await asyncio.sleep(interval_s)

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            method, path, *_ = (await reader.readline()).decode(errors="replace").split()
        except ValueError:  # not an HTTP request line (or the client went away)
            writer.close()
            return
        while (await reader.readline()).strip():
            pass  # skip headers
        body: object
        if path not in ROUTES:
            status, body = "404 Not Found", {"error": f"no such path: {path}"}
        elif method != ROUTES[path]:
            status, body = "405 Method Not Allowed", {"error": f"{path} takes {ROUTES[path]}"}
        elif path == "/stop":
            await self.bus.broadcast.stop()
            status, body = "200 OK", {"stopped": True}
        else:
            status, body = "200 OK", {str(k): v for k, v in self.state.items()}
        payload = json.dumps(body).encode()
        writer.write(
            b"HTTP/1.1 %s\r\nContent-Type: application/json\r\n"
            b"Content-Length: %d\r\nConnection: close\r\n\r\n%s"
            % (status.encode(), len(payload), payload)
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
    try:
        asyncio.run(main(args.url, args.port, args.run_for))
    except KeyboardInterrupt:  # Ctrl-C: asyncio.run has cancelled main(), which stopped the drives
        sys.exit(130)
