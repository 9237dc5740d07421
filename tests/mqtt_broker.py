"""A mosquitto broker of a test's own, shared by the MQTT tests (gateway bridge, fleet view).

Each test gets a broker on a free loopback port, in its ``tmp_path``, with
no persistence (a restart forgets every retained message), started from
the test's event loop and stopped (terminated and reaped) when the test
ends. Nothing waits a guessed time: :meth:`Broker.start` returns once the
broker's log says it runs *and* its port accepts connections, and it
leaves a retained marker (:data:`READY`) that a subscriber to ``#`` can
wait for to know it is subscribed.

Each test module declares its own two-line ``broker`` fixture around
:func:`running_broker` (importing a fixture by name would shadow it in
every test's signature, which linters flag).

A broker given a :class:`TlsListener` also listens with TLS on a port of
its own (:attr:`Broker.tls_url`), and with ``require_certificate`` there
takes only clients whose certificate its CA signed; the plain listener
stays, for the tests' own publishers and subscribers.
"""

from __future__ import annotations

import asyncio
import contextlib
import getpass
import os
import shutil
import socket
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path

from transports.bridges import wait_for_port
from waiting import wait_for

__all__ = [
    "READY",
    "TIMEOUT_S",
    "Broker",
    "TlsListener",
    "free_port",
    "publish",
    "running_broker",
    "stop_process",
    "tool",
]

#: Retained by every broker started here: a subscriber that received it is subscribed.
READY = "sjtest/ready"
#: Where Debian puts the broker (not on every user's PATH).
_SBIN = "/usr/sbin:/usr/local/sbin"
#: How long a mosquitto_pub or a stop may take (a cold start on a loaded machine).
TIMEOUT_S = 10.0


def tool(name: str) -> str:
    """The path of *name* (``mosquitto``, ``mosquitto_pub``...), looking in sbin too.

    Raises:
        RuntimeError: not installed.
    """
    path = shutil.which(name, path=f"{os.environ.get('PATH', '')}:{_SBIN}")
    if path is None:
        raise RuntimeError(f"{name} is not installed (Debian: apt-get install mosquitto)")
    return path


def free_port() -> int:
    """A loopback TCP port nobody listens on now (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port


@dataclass(frozen=True)
class TlsListener:
    """A TLS listener's files (PEM) and whether it requires a client certificate."""

    ca: Path
    cert: Path
    key: Path
    require_certificate: bool = True

    def conf(self, port: int) -> str:
        """Its lines of mosquitto.conf (they apply to the listener they follow)."""
        required = "true" if self.require_certificate else "false"
        # Started as root, mosquitto drops to user "mosquitto" before it reads the files,
        # which pytest's private tmp directory keeps from it: it stays the test's user.
        return (
            f"user {getpass.getuser()}\n"
            f"listener {port} 127.0.0.1\ncafile {self.ca}\ncertfile {self.cert}\n"
            f"keyfile {self.key}\nrequire_certificate {required}\n"
        )


@dataclass
class Broker:
    """A mosquitto of this test's own: stopped and started again on the same port at will."""

    directory: Path
    port: int = 0
    proc: asyncio.subprocess.Process | None = None
    starts: int = 0
    tls: TlsListener | None = None
    tls_port: int = 0

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    @property
    def tls_url(self) -> str:
        """The TLS listener's URL (given a :class:`TlsListener`)."""
        return f"mqtts://127.0.0.1:{self.tls_port}"

    async def start(self) -> None:
        """Start it; return once the log says it runs and its port accepts connections."""
        for _ in range(5):  # another process may take a free port before mosquitto binds it
            if self.starts == 0 or self.port == 0:
                self.port = free_port()
                self.tls_port = free_port() if self.tls is not None else 0
            if await self._start_once():
                await self.publish(READY, "1", retain=True)
                return
            if self.starts > 0:
                break
        raise AssertionError(f"mosquitto did not start: {self._log().read_text()}")

    async def _start_once(self) -> bool:
        conf = self.directory / "mosquitto.conf"
        conf.write_text(
            f"listener {self.port} 127.0.0.1\nallow_anonymous true\npersistence false\n"
            "log_dest stderr\nlog_type error\nlog_type warning\nlog_type notice\n"
            "log_type information\n" + ("" if self.tls is None else self.tls.conf(self.tls_port)),
            encoding="utf-8",
        )
        log = self._log()
        with log.open("w") as err:
            self.proc = await asyncio.create_subprocess_exec(
                tool("mosquitto"), "-c", str(conf), stdin=asyncio.subprocess.DEVNULL, stderr=err
            )
        proc = self.proc
        try:
            await wait_for(
                lambda: proc.returncode is not None or "running" in log.read_text(),
                "mosquitto to say it runs",
            )
        except AssertionError:
            await self.stop()
            raise
        if proc.returncode is not None:
            self.proc = None
            return False  # the port was taken: the log says so
        await wait_for_port(self.port)
        if self.tls is not None:
            await wait_for_port(self.tls_port)
        self.starts += 1
        return True

    def _log(self) -> Path:
        return self.directory / "mosquitto.log"

    async def stop(self) -> None:
        """Terminate it (killed if it lingers) and reap it."""
        proc, self.proc = self.proc, None
        if proc is not None:
            await stop_process(proc)

    async def publish(
        self, topic: str, payload: bytes | str | None, *, retain: bool = False
    ) -> None:
        """``mosquitto_pub`` at QoS 1 (None: empty, which clears a retained message)."""
        await publish(self, topic, payload, retain=retain)


async def stop_process(proc: asyncio.subprocess.Process, grace_s: float = TIMEOUT_S) -> None:
    """Terminate *proc*, kill it if it has not ended within *grace_s*, and reap it.

    Never an unbounded wait: a mosquitto_sub whose reader had stopped reading sat
    blocked writing to its full pipe, deaf to SIGTERM, and the suite's run with
    it, the loop with no timer left, until pytest's 120 s time-out (twice, in the
    MQTT and the Sparkplug tests' subscribers).
    """
    if proc.returncode is None:
        with contextlib.suppress(ProcessLookupError):
            proc.terminate()
        try:
            await asyncio.wait_for(proc.wait(), grace_s)
        except TimeoutError:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
    await proc.wait()


async def publish(
    broker: Broker, topic: str, payload: bytes | str | None, *, retain: bool = False
) -> None:
    """``mosquitto_pub``: one message, QoS 1; the broker has it when this returns.

    Bytes go through its standard input (``-s``), whatever they hold (a protobuf).
    """
    args = ["-h", "127.0.0.1", "-p", str(broker.port), "-q", "1", "-t", topic]
    if payload is None:
        args.append("-n")
    elif isinstance(payload, bytes):
        args.append("-s")
    else:
        args += ["-m", payload]
    proc = await asyncio.create_subprocess_exec(
        tool("mosquitto_pub"), *args, *(["-r"] if retain else []),
        stdin=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    try:
        data = payload if isinstance(payload, bytes) else b""
        _, err = await asyncio.wait_for(proc.communicate(data), TIMEOUT_S)
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()
    assert proc.returncode == 0, err.decode()


@contextlib.asynccontextmanager
async def running_broker(
    directory: Path, *, tls: TlsListener | None = None
) -> AsyncIterator[Broker]:
    """A started broker whose files live in *directory*; stopped and reaped on the way out."""
    broker = Broker(directory, tls=tls)
    await broker.start()
    try:
        yield broker
    finally:
        await broker.stop()
