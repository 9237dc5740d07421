"""The benchmarks' servers, each run in a process of its own.

``python -m benchmarks._servers sj300|pymodbus [--uvloop]`` listens on a free
loopback port, prints ``port N`` on stdout, and serves until its standard
input closes: the parent holds the pipe, so the server ends with it even if
the parent is killed. A line ``cpu`` on its standard input is answered with
``cpu SECONDS``, the process's CPU time so far, so the parent can tell the
server's share of a round trip from its own. :class:`ServerProcess` is the
parent's side.

``python -m benchmarks._servers echo`` is the floor of any asyncio stack: a
bare protocol that answers each request with a fixed reply of a status's or
a monitor's size (:data:`ECHO_REPLIES`), no parsing, no checks.

``echo`` and the minimal responders read into one reused buffer
(``_OneReadBuffer``, the way our adapter reads), so that their cost per request does not depend on
the process's history: a plain protocol's every read allocates 256 KiB,
which costs an ``mmap``/``mremap``/``munmap`` whenever glibc serves that
size by ``mmap``, in one process and not in another. The
servers' cost is in every client's wall time, and a server that happened to
start in the expensive state skewed that client's figures.

``python -m benchmarks._servers sj300-minimal`` and ``modbus-minimal`` are the
*same minimal responder* for each protocol (the tcp benchmark's headline): a
bare protocol like ``echo`` that answers each request with one fixed, valid
reply of the protocol, so that the clients' stacks are all that differs:

- ``sj300-minimal``: :data:`SJ300_STATUS_REPLY` (node 1's 14-byte status
  reply, built with the library's reply encoding) once per request, a
  request being anything up to its CR;
- ``modbus-minimal``: :data:`MODBUS_REPLY` (a read of 4 holding registers
  from device 1, 17 bytes) once per request, the request's transaction id
  copied in, which is the least a valid Modbus TCP answer needs (a request
  being an MBAP header and the length it gives).

``python -m benchmarks._servers sj300-pty --baudrate B --drives N`` serves
drives 1..N (C078 = 0, the default 1 ms processing) on a pseudo-terminal
paced at B baud 8N1, on :func:`~sj300_async.simulator.precise_event_loop`
(see there why a paced line needs it) with ``spin=True``, and prints
``path /dev/pts/M``: the wire benchmark's line. It keeps one CPU busy. The
line hands each reply character over on its own, when its stop bit ends
(``PacedLine(group_s=0)``), as a UART does: the default groups of 4 ms
(7 characters at 19200 baud) would hold every character of a group but the
last back for up to 6 character times, and wake the host once per group
instead of once per character (see ``DEFAULT_GROUP_S`` in
``sj300_async/simulator/_pacing.py``). Characters that fall due together (a
late wake-up) go out in one write.

- ``sj300``: :func:`sj300_async.simulator.serve_tcp` over a
  :class:`~sj300_async.simulator.SimulatedBus` with one drive whose
  ``processing_s`` is 0, unpaced (``pacing=LineSettings(baudrate=0)``: the
  benchmark's client opens an instant line). The simulator otherwise waits
  1 ms before each reply to emulate a real drive's processing, and a server
  hands each reply over no sooner than a 19200-baud line would, which would
  measure the emulated drive rather than the stack. The CLI (``sj300
  simulate``) does not expose either, hence this script.
- ``pymodbus``: pymodbus's ``ModbusTcpServer`` with one device (id 1) whose
  registers are one plain ``SimData`` block (pymodbus 3.16's datastore; the
  older ``ModbusServerContext`` is deprecated).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import functools
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, Literal, cast

__all__ = [
    "ECHO_REPLIES",
    "KINDS",
    "MODBUS_REGISTERS",
    "MODBUS_REPLY",
    "SJ300_STATUS_REPLY",
    "ServerKind",
    "ServerProcess",
    "main",
]

ServerKind = Literal["sj300", "pymodbus", "sj300-pty", "echo", "sj300-minimal", "modbus-minimal"]
#: Every kind, as the command line takes it.
KINDS: tuple[str, ...] = (
    "sj300",
    "pymodbus",
    "sj300-pty",
    "echo",
    "sj300-minimal",
    "modbus-minimal",
)

#: The bare round trip's replies (``echo``): sized as a status and a monitor reply.
ECHO_REPLIES: dict[bytes, bytes] = {b"S": b"S" * 14, b"M": b"M" * 110}


def _sj300_status_reply() -> bytes:
    from sj300_async.sj300 import (
        DataReply,
        InverterStatus,
        StatusA,
        StatusB,
        StatusC,
        encode_reply,
        encode_status,
    )

    running = InverterStatus(StatusA.RUNNING, StatusB.RUNNING, StatusC.CONSTANT_SPEED)
    return encode_reply(DataReply(1, encode_status(running)))


#: ``sj300-minimal``'s answer to every request: node 1's command 04 reply (14 bytes).
SJ300_STATUS_REPLY: bytes = _sj300_status_reply()
#: Registers ``modbus-minimal`` answers with: a read of this many holding registers.
MODBUS_REGISTERS = 4
#: ``modbus-minimal``'s answer after the transaction id: protocol 0, length, device 1,
#: function 3, byte count, the registers 0..3 (17 bytes with the id).
MODBUS_REPLY: bytes = bytes(
    (0, 0, 0, 3 + 2 * MODBUS_REGISTERS, 1, 3, 2 * MODBUS_REGISTERS)
) + b"".join(n.to_bytes(2, "big") for n in range(MODBUS_REGISTERS))

#: Holding registers the pymodbus server offers (the benchmark reads at most 50).
_REGISTERS = 256
# The folder that holds the benchmarks package, as this process found it.
_ROOT = Path(__file__).parent.parent


def _answer_parent() -> None:
    for line in sys.stdin:
        if line.strip() == "cpu":
            print(f"cpu {time.process_time()!r}", flush=True)


async def _stdin_closed() -> None:
    """Answer the parent's questions; return when it closes standard input (or dies)."""
    loop = asyncio.get_running_loop()
    await loop.run_in_executor(None, _answer_parent)


async def _serve_sj300() -> None:
    from sj300_async import LineSettings
    from sj300_async.simulator import serve_tcp
    from sj300_async.simulator.sj300 import SimulatedBus

    # No line behind the socket (the client says so too): answer at once.
    server = await serve_tcp(
        SimulatedBus(nodes=[1], processing_s=0.0), pacing=LineSettings(baudrate=0)
    )
    print(f"port {server.port}", flush=True)
    try:
        await _stdin_closed()
    finally:
        server.close()
        await server.wait_closed()


class _OneReadBuffer(asyncio.BufferedProtocol, asyncio.Protocol):
    """Socket reads into one buffer kept for the connection, copied out as ``bytes``.

    The library's ``BufferedReads`` written again on purpose: this module
    runs pymodbus's reference server too, and importing the library there
    changed that process enough to move pymodbus's gateway reference (the
    memory layout and allocator state a process ends up in after its imports;
    see :mod:`benchmarks._allocator`). The servers import nothing of the
    library at start-up.
    """

    def __init__(self) -> None:
        self._view = memoryview(bytearray(16384))

    def get_buffer(self, sizehint: int) -> memoryview:
        return self._view

    def buffer_updated(self, nbytes: int) -> None:
        self.data_received(self._view[:nbytes].tobytes())


class _Echo(_OneReadBuffer):
    """Answers each request with the reply its first byte names; nothing else."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # A cast, not isinstance(): uvloop's transports do not derive from asyncio's.
        self._transport = cast(asyncio.Transport, transport)

    def data_received(self, data: bytes) -> None:
        self._transport.write(ECHO_REPLIES[data[:1]])


class _Sj300Minimal(_OneReadBuffer):
    """Answers every request (up to its CR) with node 1's status reply; nothing else."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.Transport, transport)

    def data_received(self, data: bytes) -> None:
        requests = data.count(13)  # CR ends a request
        if requests:
            self._transport.write(SJ300_STATUS_REPLY * requests)


class _ModbusMinimal(_OneReadBuffer):
    """Answers every Modbus TCP request with :data:`MODBUS_REPLY` under its transaction id."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.Transport, transport)
        self._buffer = b""

    def data_received(self, data: bytes) -> None:
        buffer = self._buffer + data if self._buffer else data
        # An MBAP header (7 bytes) gives the length of what follows its first 6.
        while len(buffer) >= 7 and len(buffer) >= 6 + int.from_bytes(buffer[4:6], "big"):
            self._transport.write(buffer[:2] + MODBUS_REPLY)
            buffer = buffer[6 + int.from_bytes(buffer[4:6], "big") :]
        self._buffer = buffer


async def _serve_echo() -> None:
    await _serve_bare(_Echo)


async def _serve_sj300_minimal() -> None:
    await _serve_bare(_Sj300Minimal)


async def _serve_modbus_minimal() -> None:
    await _serve_bare(_ModbusMinimal)


async def _serve_bare(protocol: Callable[[], asyncio.Protocol]) -> None:
    loop = asyncio.get_running_loop()
    server = await loop.create_server(protocol, "127.0.0.1", 0)
    print(f"port {server.sockets[0].getsockname()[1]}", flush=True)
    try:
        await _stdin_closed()
    finally:
        server.close()
        await server.wait_closed()


async def _serve_sj300_pty(baudrate: int, drives: int) -> None:
    from sj300_async import LineSettings
    from sj300_async.simulator import PacedLine, open_pty_server
    from sj300_async.simulator.sj300 import SimulatedBus

    bus = SimulatedBus(nodes=range(1, drives + 1), wait_ms=0)
    # One character at a time, at the end of its stop bit: a UART (see above).
    line = PacedLine(LineSettings(baudrate), group_s=0.0)
    server = await open_pty_server(bus, line=line)
    print(f"path {server.path}", flush=True)
    try:
        await _stdin_closed()
    finally:
        server.close()


async def _serve_pymodbus() -> None:
    from pymodbus.server import ModbusTcpServer
    from pymodbus.simulator import DataType, SimData, SimDevice

    registers = SimData(
        0, count=_REGISTERS, values=list(range(_REGISTERS)), datatype=DataType.REGISTERS
    )
    server = ModbusTcpServer(SimDevice(1, [registers]), address=("127.0.0.1", 0))
    await server.serve_forever(background=True)
    listener: Any = server.transport  # asyncio.Server, or uvloop's own Server
    print(f"port {listener.sockets[0].getsockname()[1]}", flush=True)
    try:
        await _stdin_closed()
    finally:
        await server.shutdown()  # type: ignore[no-untyped-call]


class ServerProcess:
    """A benchmark server in a child process; a context manager that yields its port.

    Raises (on enter):
        RuntimeError: the server did not report a port (its stderr is quoted).
    """

    def __init__(
        self,
        kind: str,
        *,
        uvloop: bool = False,
        baudrate: int = 0,
        drives: int = 1,
        module: str = "benchmarks._servers",
        args: Sequence[str] = (),
    ) -> None:
        """Run ``python -m MODULE KIND [ARGS...]``: this module's servers by default."""
        self.kind = kind
        #: What the server reported: a TCP port, or a pty's path (``sj300-pty``).
        self.port = 0
        self.path = ""
        self._args = [sys.executable, "-m", module, kind, *args]
        if uvloop:
            self._args.append("--uvloop")
        if kind == "sj300-pty":
            self._args += ["--baudrate", str(baudrate), "--drives", str(drives)]
        self._process: subprocess.Popen[str] | None = None

    def __enter__(self) -> ServerProcess:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(_ROOT), env.get("PYTHONPATH", "")) if p)
        process = subprocess.Popen(
            self._args,
            cwd=_ROOT,
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self._process = process
        assert process.stdout is not None
        line = process.stdout.readline()
        if line.startswith("port "):
            self.port = int(line.split()[1])
        elif line.startswith("path "):
            self.path = line.split()[1]
        else:
            assert process.stdin is not None
            assert process.stderr is not None
            process.stdin.close()
            error = process.stderr.read()
            self.__exit__(None, None, None)
            raise RuntimeError(f"{self.kind} server did not start: {line}{error}")
        return self

    def cpu_seconds(self) -> float:
        """The server process's CPU time so far (user + system), in seconds.

        Raises:
            RuntimeError: the server is not running, or did not answer.
        """
        return float(self.ask("cpu")[0])

    def dump_and_kill(self) -> str:
        """Abort the child (SIGABRT: a child with faulthandler prints its stacks); its stderr."""
        process = self._process
        if process is None:
            return ""
        # SIGUSR1 first: a child that installed a handler prints its asyncio tasks'
        # stacks (what its event loop waits for), which faulthandler cannot show.
        process.send_signal(signal.SIGUSR1)
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(timeout=1)
        process.send_signal(signal.SIGABRT)
        try:
            process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        return process.stderr.read() if process.stderr is not None else ""

    def ask(self, command: str) -> list[str]:
        """Send *command* on the child's stdin; the words of its answer after the echoed command.

        Raises:
            RuntimeError: the server is not running, or did not answer.
        """
        process = self._process
        if process is None or process.stdin is None or process.stdout is None:
            raise RuntimeError(f"{self.kind} server is not running")
        process.stdin.write(f"{command}\n")
        process.stdin.flush()
        answer = process.stdout.readline().split()
        if not answer or answer[0] != command:
            raise RuntimeError(f"{self.kind} server answered {answer!r} to {command}")
        return answer[1:]

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        process, self._process = self._process, None
        if process is None:
            return
        assert process.stdin is not None
        process.stdin.close()
        try:
            process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        for stream in (process.stdout, process.stderr):
            if stream is not None:
                stream.close()


def main(argv: Sequence[str] | None = None) -> int:
    """Serve until standard input closes; return the exit status."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks._servers")
    parser.add_argument("kind", choices=KINDS)
    parser.add_argument("--uvloop", action="store_true", help="serve on uvloop")
    parser.add_argument("--baudrate", type=int, default=19200, help="sj300-pty: line speed")
    parser.add_argument("--drives", type=int, default=32, help="sj300-pty: drives 1..N")
    args = parser.parse_args(argv)
    if args.kind == "sj300-pty":
        from sj300_async.simulator import precise_event_loop

        # Spinning: the process stands in for hardware that never sleeps (a
        # UART, a drive's controller), so its own wake-up latency must not
        # count against the host measured on the other end of the pty.
        spinning = functools.partial(precise_event_loop, spin=True)
        with asyncio.Runner(loop_factory=spinning) as runner:
            runner.run(_serve_sj300_pty(args.baudrate, args.drives))
        return 0
    serve = {
        "sj300": _serve_sj300,
        "pymodbus": _serve_pymodbus,
        "echo": _serve_echo,
        "sj300-minimal": _serve_sj300_minimal,
        "modbus-minimal": _serve_modbus_minimal,
    }[args.kind]
    if args.uvloop:
        import uvloop

        uvloop.run(serve())
    else:
        asyncio.run(serve())
    return 0


if __name__ == "__main__":
    sys.exit(main())
