"""``sj300 simulate``: serve simulated drives over TCP, a pty or a serial port until interrupted.

``--tap tcp://HOST:PORT`` mirrors the TCP listeners' line to each client
of the tap (``tap on tcp://...`` on stdout), for ``sj300 sniff``: see
:mod:`sj300_async.simulator._tap`. A pty or device line is not mirrored.

stdout carries one line per listener, ``listening on tcp://127.0.0.1:4001``
or ``listening on /dev/pts/5`` (``--pty``, or ``--device`` for a port that
exists already), flushed at once so a script can read the
real port (when given port 0) or the pty path; demo trips are reported
there too. Everything else (the summary, warnings) goes to stderr.

SIGINT and SIGTERM stop it cleanly: listeners and client connections are
closed, pending replies cancelled. The exit status is 130 after SIGINT
(Ctrl-C, as every command) and 0 after SIGTERM (a service manager's stop).

``--protocol NAME`` serves another registered protocol's drives (FR-700:
stations 0..31). The command knows no protocol: each protocol's simulator
declares the options only its line takes, in an argument group of their
own (SJ300 ``--country``; FR-700 ``--no-wait-field``, ``--terminator``), and
builds its line from them (:mod:`sj300_async.simulator._command_line`). The
default ``--nodes`` is the first address of the protocol's range (SJ300
node 1, FR-700 station 0).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib
import logging
import random
import signal
import sys
from typing import TYPE_CHECKING, Any

from ..bus import DEFAULT_PROTOCOL, get_dialect, parse_node_list, protocol_names
from ..simulator import (
    LinePacing,
    PacedLine,
    PlausibleLine,
    SimulateCommandLine,
    SimulateSettings,
    SimulatorServer,
    TapServer,
    precise_event_loop,
    serve_tap,
    serve_tcp,
)
from ..wire import LocalProtocolError
from ._args import DEFAULT_PORT, LOOPBACK, ListenAddress, format_nodes, parse_listen
from ._common import positive_float
from ._errors import EXIT_ON_SIGNAL, CliError

if TYPE_CHECKING:  # POSIX-only (pty, termios): imported where used, so --help works without them
    from ..simulator import PtyServer, SerialDeviceServer

__all__ = ["add_parser"]


def _command_lines() -> dict[str, SimulateCommandLine]:
    """Each registered protocol's part of ``sj300 simulate``, for those whose simulator has one.

    It is the ``COMMAND_LINE`` attribute of the module the dialect's ``simulator``
    entry names (:mod:`sj300_async.simulator._command_line`).
    """
    found = {}
    for name in protocol_names():
        module = importlib.import_module(get_dialect(name).simulator.partition(":")[0])
        command_line: SimulateCommandLine | None = getattr(module, "COMMAND_LINE", None)
        if command_line is not None:
            found[name] = command_line
    return found


def _wait_ms(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= 1000:
        raise argparse.ArgumentTypeError(f"--wait-ms is 0..1000 (C078), got {text!r}")
    return value


def add_parser(subparsers: Any) -> None:
    """Add ``simulate`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "simulate",
        help="serve simulated SJ300 (or FR-700) drives over TCP or a pseudo-terminal",
        description="Serve simulated SJ300 drives (or another protocol's, with --protocol: "
        "Mitsubishi FR-700) on a virtual RS-485 line until interrupted.",
    )
    p.add_argument(
        "--listen",
        action="append",
        type=parse_listen,
        metavar="URL",
        help=f"serve over TCP at tcp://HOST:PORT (repeatable; port 0 picks one); "
        f"default tcp://{LOOPBACK}:{DEFAULT_PORT} unless --pty is given",
    )
    p.add_argument("--pty", action="store_true", help="serve on a pseudo-terminal, print its path")
    p.add_argument(
        "--tap",
        type=parse_listen,
        metavar="URL",
        help="mirror every byte of the TCP listeners' line, both directions, to each client "
        "of tcp://HOST:PORT, like a listen-only transceiver (for `sj300 sniff`); "
        "what a client sends is ignored",
    )
    p.add_argument(
        "--device",
        action="append",
        metavar="PATH",
        help="serve on this serial device (a real port, or one end of a socat pty pair); "
        "--baud etc. set its UART",
    )
    command_lines = _command_lines()
    p.add_argument(
        "--protocol",
        choices=tuple(command_lines),
        default=DEFAULT_PROTOCOL,
        help=f"the drives' protocol (default {DEFAULT_PROTOCOL})",
    )
    p.add_argument(
        "--nodes",
        metavar="LIST",
        help="drive addresses, e.g. 1-8,12,20-22 (default 1; FR-700 stations 0..31, default 0)",
    )
    p.add_argument(
        "--wait-ms",
        type=_wait_ms,
        metavar="MS",
        help="set C078 on every drive (FR-700: Pr.123 0..150, with --no-wait-field)",
    )
    p.add_argument(
        "--factory-defaults",
        action="store_true",
        help="start with true factory values (A001=A002=01: serial run/frequency refused)",
    )
    for command_line in command_lines.values():
        group = p.add_argument_group(command_line.title)
        for option in command_line.options:
            if option.switch:
                group.add_argument(option.flag, dest=option.dest, action="store_true",
                                   help=option.help)  # fmt: skip
            else:
                group.add_argument(
                    option.flag,
                    dest=option.dest,
                    choices=option.choices or None,
                    default=option.default,
                    help=option.help,
                )
    line = p.add_argument_group("serial line")
    line.add_argument(
        "--baud",
        type=int,
        metavar="BPS",
        help="line speed (default 19200): TCP listeners answer as soon as a line at this "
        "speed could carry the frames (--pace: every character at its wire time)",
    )
    # No defaults here: any of them given means a line was described (default 8N1).
    line.add_argument("--bytesize", type=int, choices=(7, 8), help="data bits (default 8)")
    line.add_argument(
        "--parity", type=str.upper, choices=("N", "E", "O"), help="parity (default N)"
    )
    line.add_argument("--stopbits", type=int, choices=(1, 2), help="stop bits (default 1)")
    line.add_argument(
        "--pace",
        action="store_true",
        help="hold every byte for its wire time at the line settings",
    )
    p.add_argument(
        "--trip-every",
        type=positive_float,
        metavar="SECONDS",
        help="demo: trip a random running drive this often",
    )
    p.add_argument("--seed", type=int, help="seed for --trip-every's choices")
    p.add_argument("-v", "--verbose", action="count", default=0, help="log more (-vv: debug)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Serve until SIGINT / SIGTERM; return 130 after SIGINT, 0 after SIGTERM."""
    if args.verbose:
        logging.basicConfig(
            level=logging.DEBUG if args.verbose > 1 else logging.INFO,
            format="%(asctime)s %(name)s %(levelname)s %(message)s",
        )
    elsewhere = args.pty or args.device
    listen: list[ListenAddress] = args.listen or ([] if elsewhere else [parse_listen("tcp://")])
    # --parity E alone is a line too (8E2 carries a frame slower than 8N1): it was
    # ignored unless --baud came with it.
    framing = (args.bytesize, args.parity, args.stopbits)
    line_given = args.baud is not None or args.pace or any(f is not None for f in framing)
    try:
        pacing = LinePacing(
            args.baud or 19200, args.bytesize or 8, args.parity or "N", args.stopbits or 1
        )
        command_lines = _command_lines()
        command_line = command_lines[args.protocol]
        _refuse_other_protocols_options(args, command_lines)
        low, high = get_dialect(args.protocol).node_range
        noun = get_dialect(args.protocol).node_noun
        nodes = parse_node_list(args.nodes or str(low), low=low, high=high, noun=noun)
        settings_of_line = SimulateSettings(
            nodes,
            factory_defaults=args.factory_defaults,
            wait_ms=args.wait_ms,
            line=pacing if line_given else None,
            options={o.dest: getattr(args, o.dest) for o in command_line.options},
        )
        bus = command_line.build(settings_of_line)
    except LocalProtocolError as exc:
        raise CliError(str(exc)) from None
    for address in listen:
        if not address.is_loopback:
            print(f"warning: {address} is reachable from the network", file=sys.stderr)
    shared_line = PacedLine(pacing) if args.pace else None
    settings = pacing if line_given else None
    # A paced line's timers are the wire: they need sub-millisecond precision.
    factory = precise_event_loop if shared_line is not None else None
    with asyncio.Runner(loop_factory=factory) as runner:
        return runner.run(
            _serve(args, command_line, settings_of_line, bus, listen, shared_line, settings)
        )


def _refuse_other_protocols_options(
    args: argparse.Namespace, command_lines: dict[str, SimulateCommandLine]
) -> None:
    """An option of another protocol's simulator, given: exit 2 rather than ignore it."""
    for name, command_line in command_lines.items():
        if name == args.protocol:
            continue
        for option in command_line.options:
            if getattr(args, option.dest, None) not in (None, False, option.default):
                raise CliError(
                    f"{option.flag} is an option of {name} drives, not of {args.protocol} "
                    f"drives (--protocol {name})"
                )


async def _serve(
    args: argparse.Namespace,
    command_line: SimulateCommandLine,
    simulated: SimulateSettings,
    bus: Any,
    listen: list[ListenAddress],
    line: PacedLine | None,
    settings: LinePacing | None,
) -> int:
    loop = asyncio.get_running_loop()
    noun = get_dialect(args.protocol).node_noun
    stop = asyncio.Event()
    stopped_by: list[signal.Signals] = []  # the first stopping signal sets the status

    def on_signal(sig: signal.Signals) -> None:
        stopped_by.append(sig)
        stop.set()

    for sig in EXIT_ON_SIGNAL:
        loop.add_signal_handler(sig, on_signal, sig)
    servers: list[SimulatorServer] = []
    tap: TapServer | None = None
    ttys: list[PtyServer | SerialDeviceServer] = []
    tripper: asyncio.Task[None] | None = None
    try:
        if args.tap is not None:
            try:
                tap = await serve_tap(args.tap.host, args.tap.port)
            except OSError as exc:
                raise CliError(f"cannot listen on {args.tap}: {exc.strerror or exc}") from None
            print(f"tap on {ListenAddress(tap.host, tap.port)}", flush=True)
        for address in listen:
            try:
                server = await serve_tcp(
                    bus,
                    address.host,
                    address.port,
                    # --baud without --pace: answer as soon as that line allows
                    # (the default is a 19200-baud line's plausibility).
                    line=line or (PlausibleLine(settings) if settings else None),
                    tap=None if tap is None else tap.mirror,
                )
            except OSError as exc:
                raise CliError(f"cannot listen on {address}: {exc.strerror or exc}") from None
            servers.append(server)
            print(f"listening on {ListenAddress(server.host, server.port)}", flush=True)
        if args.pty:
            from ..simulator import open_pty_server

            try:
                ttys.append(await open_pty_server(bus, line=line))
            except OSError as exc:
                raise CliError(f"cannot open a pseudo-terminal: {exc.strerror or exc}") from None
            print(f"listening on {ttys[-1].path}", flush=True)
        for path in args.device or ():
            from ..simulator import serve_serial_device

            try:
                ttys.append(await serve_serial_device(bus, path, settings=settings, line=line))
            except (OSError, LocalProtocolError) as exc:
                why = exc.strerror if isinstance(exc, OSError) else exc
                raise CliError(f"cannot serve on {path}: {why or exc}") from None
            print(f"listening on {path}", flush=True)
        mode = command_line.describe(bus, simulated)
        pace = ""
        if settings is not None:  # the line the listeners answer as (its framing too)
            framing = f"{settings.bytesize}{settings.parity}{settings.stopbits}"
            verb = "paced at" if line else "answering as"
            pace = f", {verb} {settings.baudrate} bps {framing}"
        print(
            f"simulating {noun}(s) {format_nodes(sorted(bus.drives))} ({mode}{pace}); "
            "Ctrl-C to stop",
            file=sys.stderr,
            flush=True,
        )
        if args.trip_every:
            tripper = asyncio.create_task(
                _trip_periodically(
                    bus, command_line, noun, args.trip_every, random.Random(args.seed)
                )
            )
        await stop.wait()
    finally:
        if tripper is not None:
            tripper.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await tripper
        for server in servers:
            server.close()
        for server in servers:
            await server.wait_closed()
        if tap is not None:
            tap.close()
            await tap.wait_closed()
        for tty in ttys:
            tty.close()
        for sig in EXIT_ON_SIGNAL:
            loop.remove_signal_handler(sig)
    return EXIT_ON_SIGNAL[stopped_by[0]]


async def _trip_periodically(
    bus: Any, command_line: SimulateCommandLine, noun: str, every_s: float, rng: random.Random
) -> None:
    """Demo: every *every_s*, trip one running drive with the over-current code of its phase."""
    loop = asyncio.get_running_loop()
    while True:
        await asyncio.sleep(every_s)
        now = loop.time()
        running = [d for d in bus.drives.values() if d.state(now).outputting]
        if not running:
            continue
        drive = rng.choice(running)
        if drive.trip(now=now):
            name = command_line.trip_name(drive)
            print(f"{noun} {drive.node:02d} tripped: {name}", flush=True)
