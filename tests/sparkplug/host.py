"""A Sparkplug host of the tests' own: mosquitto_sub receives, Eclipse Tahu's codec decodes.

Neither part is ours: ``mosquitto_sub`` prints each message's retain flag,
topic and payload in hex, and ``node codec.mjs`` (sparkplug-payload, the
JavaScript codec of Eclipse Tahu, from its lockfile by ``make
node-packages``) decodes each payload, and encodes the commands the tests
send (published by ``mosquitto_pub``). A test reads :attr:`Host.messages`
in the order the broker delivered them and waits for a state with
:meth:`Host.until`, never for a time.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import shutil
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mqtt_broker import READY, TIMEOUT_S, Broker, stop_process, tool
from waiting import wait_for

__all__ = ["NODE_DIR", "Codec", "Host", "SpbMessage", "codec", "host"]

NODE_DIR = Path(__file__).parent / "node"
Json = Any


class Codec:
    """``node codec.mjs``: one process, requests answered in order."""

    def __init__(self, process: asyncio.subprocess.Process) -> None:
        self.process = process
        self._lock = asyncio.Lock()

    async def _ask(self, request: Json) -> Json:
        assert self.process.stdin is not None
        assert self.process.stdout is not None
        async with self._lock:
            self.process.stdin.write(json.dumps(request).encode() + b"\n")
            await self.process.stdin.drain()
            async with asyncio.timeout(10):
                line = await self.process.stdout.readline()
        assert line, "the Tahu codec ended"
        answer = json.loads(line)
        assert "ok" in answer, f"the Tahu codec failed: {answer}"
        return answer["ok"]

    async def decode(self, payload: bytes, types: dict[str, str] | None = None) -> Json:
        """*payload* as sparkplug-payload decodes it (64-bit numbers as numbers).

        *types*: each alias's datatype, as its birth said (data messages carry none).
        """
        request: Json = {"decode": payload.hex()}
        if types is not None:
            request["types"] = types
        return await self._ask(request)

    async def encode(self, payload: Json) -> bytes:
        """*payload* (sparkplug-payload's form: ``{"timestamp", "metrics": [...]}``) encoded."""
        return bytes.fromhex(await self._ask({"encode": payload}))


@contextlib.asynccontextmanager
async def codec() -> AsyncIterator[Codec]:
    node = shutil.which("node")
    if node is None:
        raise RuntimeError("node is not installed (the tests need Node.js >= 20 and npm)")
    if not (NODE_DIR / "node_modules" / "sparkplug-payload").is_dir():
        raise RuntimeError("sparkplug-payload is not installed: make node-packages")
    process = await asyncio.create_subprocess_exec(
        node, str(NODE_DIR / "codec.mjs"),
        stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
    )  # fmt: skip
    try:
        yield Codec(process)
    finally:
        if process.stdin is not None:
            process.stdin.close()
        try:
            async with asyncio.timeout(5):
                await process.wait()
        except TimeoutError:
            process.kill()
            await process.wait()


@dataclass(frozen=True)
class SpbMessage:
    """One Sparkplug message as the host received it."""

    topic: str
    retained: bool
    #: The message type: NBIRTH, DDATA, ...
    kind: str
    #: The device id, None for the edge node's own messages.
    device: str | None
    #: The payload as Tahu decodes it.
    payload: Json

    @property
    def seq(self) -> int | None:
        seq = self.payload.get("seq")
        return None if seq is None else int(seq)

    def metrics(self) -> dict[str, Json]:
        """The metrics by name (births) or by alias as text (data)."""
        return {
            str(m["name"]) if "name" in m else str(m["alias"]): m
            for m in self.payload.get("metrics", [])
        }

    def value(self, name: str) -> Json:
        return self.metrics()[name]["value"]


@dataclass
class Host:
    """What the broker delivered on ``spBv1.0/#``, decoded, in order."""

    broker: Broker
    codec: Codec
    group: str
    edge: str
    messages: list[SpbMessage] = field(default_factory=list)
    #: Each alias's datatype as the births said, by device (None: the edge node's).
    types: dict[str | None, dict[str, str]] = field(default_factory=dict)
    #: Payloads Tahu could not decode (a test fails on any).
    undecodable: list[str] = field(default_factory=list)

    def of(self, kind: str, device: str | None = None) -> list[SpbMessage]:
        return [
            m for m in self.messages if m.kind == kind and (device is None or m.device == device)
        ]

    async def until(
        self,
        predicate: Callable[[SpbMessage], bool],
        what: str,
        count: int = 1,
        timeout: float = 10,
    ) -> list[SpbMessage]:
        """The messages matching *predicate*, once there are at least *count* of them."""
        await wait_for(
            lambda: sum(1 for m in self.messages if predicate(m)) >= count, what, timeout=timeout
        )
        return [m for m in self.messages if predicate(m)]

    def topic(self, kind: str, device: str | None = None) -> str:
        base = f"spBv1.0/{self.group}/{kind}/{self.edge}"
        return base if device is None else f"{base}/{device}"

    async def command(self, kind: str, metrics: list[Json], device: str | None = None,
                      *, retain: bool = False) -> None:  # fmt: skip
        """An NCMD or DCMD, encoded by Tahu, published by mosquitto_pub (QoS 1)."""
        payload = await self.codec.encode({"timestamp": 1, "metrics": metrics})
        await self.broker.publish(self.topic(kind, device), payload, retain=retain)

    async def raw(self, kind: str, payload: bytes, device: str | None = None) -> None:
        await self.broker.publish(self.topic(kind, device), payload)


@contextlib.asynccontextmanager
async def host(
    broker: Broker, tahu: Codec, *, group: str = "plant", edge: str = "gw1"
) -> AsyncIterator[Host]:
    """A subscriber to ``spBv1.0/#``; subscribed when this enters (it got the READY marker)."""
    proc = await asyncio.create_subprocess_exec(
        tool("mosquitto_sub"), "-p", str(broker.port), "-q", "1", "-t", "spBv1.0/#", "-t", READY,
        "-F", "%r %t %x", stdout=asyncio.subprocess.PIPE,
    )  # fmt: skip
    found = Host(broker, tahu, group, edge)
    ready = asyncio.Event()

    async def read() -> None:
        assert proc.stdout is not None
        while line := await proc.stdout.readline():
            retained, topic, hexed = ([*line.decode().rstrip("\n").split(" ", 2), ""])[:3]
            if topic == READY:
                ready.set()
                continue
            parts = topic.split("/")
            if parts[2] == "STATE" or parts[1] == "STATE":
                continue
            kind, device = parts[2], (parts[4] if len(parts) > 4 else None)
            data = kind in ("NDATA", "DDATA")
            try:
                payload = await tahu.decode(
                    bytes.fromhex(hexed), found.types.get(device, {}) if data else None
                )
            except AssertionError as exc:
                if kind not in ("NCMD", "DCMD"):  # a test's own bad commands are meant
                    found.undecodable.append(f"{topic}: {exc}")
                continue
            if kind in ("NBIRTH", "DBIRTH"):
                found.types[device] = {
                    str(m["alias"]): m["type"] for m in payload["metrics"] if "alias" in m
                }
            found.messages.append(SpbMessage(topic, retained == "1", kind, device, payload))

    reader = asyncio.create_task(read())
    try:
        await wait_for(ready.is_set, "the Sparkplug host to be subscribed")
        yield found
    finally:
        await stop_process(proc)
        await asyncio.wait_for(reader, TIMEOUT_S)  # a reader's failure is raised here
    assert found.undecodable == [], found.undecodable
