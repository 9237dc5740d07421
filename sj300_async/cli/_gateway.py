"""``sj300 gateway``: own the lines, poll the drives, serve them through the northbounds.

``--config gateway.toml`` describes everything (several lines, write
grants, leases; docs/GATEWAY.md); the flags cover the simple case, one
read-only line: ``--url URL --nodes LIST [--protocol NAME] --id NAME`` and
one flag per registered northbound that has one (``--modbus HOST:PORT``,
``--http HOST:PORT``, ``--mqtt mqtt://HOST:PORT``, ``--opcua opc.tcp://HOST:PORT``:
each northbound declares its own, :class:`~sj300_async.gateway.Flag`). A bad configuration
starts nothing (exit 2, one line naming the file, line and key).

stdout carries one line per northbound, as it announces itself (``modbus
on 127.0.0.1:1502``, ``metrics on http://127.0.0.1:9300/metrics``, ``mqtt
to mqtt://127.0.0.1:1883 as gw1``: the broker is connected to in the
background, the line says where, not that it answered), flushed at once so
that a script can read the real port when it asked for port 0. SIGINT and
SIGTERM stop it cleanly (docs/GATEWAY.md: the order, and the one command it
may send on the way out), also while it is still starting; exit status 0
after SIGTERM, 130 after SIGINT (Ctrl-C), as every other command. SIGHUP
reads the ``--config`` file again and applies what changed (:mod:`._hangup`). A line
that cannot connect at start is served down and retried; a northbound that
cannot listen (its port in use, an address not on this host) is one line
naming it, exit status 2.
"""

from __future__ import annotations

import argparse
import asyncio
import importlib.util
import logging
import signal
import sys
from typing import TYPE_CHECKING, Any

from ..bus import protocol_names
from ..gateway import (
    DEFAULT_STALE_AFTER_S,
    GatewayConfig,
    config_from_flags,
    get_northbound,
    load_config,
    northbound_extra,
    northbound_names,
)
from ._demo import DEMO_NODES, DEMO_URL, demo_running
from ._errors import EXIT_ON_SIGNAL, USAGE, CliError
from ._hangup import HangupReloads, status_line
from ._install import gateway_install_command

if TYPE_CHECKING:
    from ..gateway import Gateway, ServiceManager

__all__ = ["DEMO_HTTP", "add_parser"]

#: Where ``--demo`` serves the workbench when no other northbound is named.
DEMO_HTTP = "127.0.0.1:8080"


def add_parser(subparsers: Any) -> None:
    """Add ``gateway`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "gateway",
        help="own the lines and serve the drives over Modbus TCP, OPC UA, MQTT and HTTP",
        description="Own one or more RS-485 lines, poll their drives and serve them: "
        "Modbus TCP for SCADA (a unit id per drive), OPC UA (the opcua extra), MQTT with "
        "Home Assistant discovery and Sparkplug B, and over HTTP the workbench, its API, "
        "/metrics and /healthz. Read-only unless the --config file grants writes. "
        "Needs the gateway extra.",
    )
    p.add_argument("--config", metavar="FILE", help="the gateway's TOML configuration")
    p.add_argument(
        "--check-config",
        metavar="FILE",
        help="check FILE as a start would (the TOML, lines, grants, users, certificates, "
        "ports free) without opening a line or a port; print a summary (exit 0) or the "
        "start's one-line error (exit 2)",
    )
    p.add_argument(
        "--no-port-check",
        dest="port_check",
        action="store_false",
        help="with --check-config: leave the listening ports out (checking beside the "
        "running gateway, whose ports are in use)",
    )
    # Its own --url and --protocol: the bus options of other commands (--timeout,
    # --trace...) do not apply to a process that owns several lines.
    p.add_argument("--url", default=None, help="the one line's bus URL (without --config)")
    p.add_argument(
        "--protocol", default=None, help=f"with --url: the line's protocol ({_protocols()})"
    )
    p.add_argument("--nodes", metavar="LIST", help="with --url: the drives to poll, e.g. 1-8")
    p.add_argument(
        "--demo",
        action="store_true",
        help=f"serve eight simulated drives that move and trip ({DEMO_URL}); "
        f"with no other flag, the workbench on http://{DEMO_HTTP}/",
    )
    for section, flag in _flags():
        p.add_argument(
            flag.option, *flag.aliases, dest=_dest(section), metavar=flag.metavar, help=flag.help
        )
    p.add_argument(
        "--id", metavar="NAME", help="the gateway's name on MQTT (default: the host name)"
    )
    p.add_argument(
        "--stale-after",
        type=float,
        default=None,
        metavar="S",
        help="with --url: serve values read longer ago than this as stale (default 5 s)",
    )
    p.add_argument("--interval", type=float, default=None, metavar="S", help="poll interval")
    p.add_argument(
        "--capture",
        metavar="PATH",
        help="write every line's frames to PATH, a pcapng file (one interface per line)",
    )
    p.add_argument(
        "--hash-password",
        action="store_true",
        help="read a password (prompted, or a line on stdin) and print its hash for "
        "[[http.users]] password_hash, then exit",
    )
    p.add_argument(
        "--new-token",
        metavar="NAME",
        help="print a new API token for a script and the [[http.tokens]] entry that "
        "admits it, then exit",
    )
    p.add_argument(
        "--decommission",
        action="store_true",
        help="clear everything this gateway id left retained on its [mqtt] broker (states, "
        "availability, Home Assistant's configs: its devices go), then exit; run it with "
        "the gateway stopped",
    )
    p.add_argument(
        "--no-collector-tuning",
        dest="tune_collector",
        action="store_false",
        help="leave Python's garbage collector as it is (by default the start-up's objects "
        "are frozen and young collections run less often: docs/GATEWAY.md)",
    )
    p.add_argument("-v", "--verbose", action="count", default=0, help="log more (-vv: debug)")
    p.set_defaults(run=run)


def _hash_password() -> int:
    import getpass

    from ..gateway.http import hash_password

    if sys.stdin.isatty():
        password = getpass.getpass("password: ")
        if getpass.getpass("again: ") != password:
            raise CliError("the two passwords differ")
    else:
        password = sys.stdin.readline().rstrip("\r\n")
    if len(password) < 8:
        raise CliError("a password of at least 8 characters, please")
    print(hash_password(password))
    return 0


def _new_token(name: str) -> int:
    from ..gateway.http import hash_token, new_token

    token = new_token()
    print(f"token (give it to the script; it is not stored): {token}")
    print("the gateway's configuration:")
    print(f'[[http.tokens]]\nname = "{name}"\ntoken_hash = "{hash_token(token)}"')
    return 0


def _protocols() -> str:
    return ", ".join(protocol_names())


def _flags() -> list[tuple[str, Any]]:
    """``(section, Flag)`` of every registered northbound that has a flag."""
    out = []
    for section in northbound_names():
        flag = get_northbound(section).flag
        if flag is not None:
            out.append((section, flag))
    return out


def _dest(section: str) -> str:
    return f"northbound_{section}"


def _config(args: argparse.Namespace) -> GatewayConfig:
    flags = _flags()
    given = {section: getattr(args, _dest(section)) for section, _ in flags}
    given = {section: value for section, value in given.items() if value is not None}
    options = ", ".join(["--url", "--nodes", *(flag.option for _, flag in flags), "--id"])
    if args.config is not None:
        if args.url or args.nodes or given or args.id or args.demo:
            raise CliError(f"--config describes everything: no {options}, --demo")
        return load_config(args.config)
    if args.demo:
        if args.url or args.nodes:
            raise CliError("--demo serves its own simulated line: no --url, --nodes")
        args.url, args.nodes = DEMO_URL, DEMO_NODES
        given = given or {"http": DEMO_HTTP}
    if not args.url or not args.nodes:
        raise CliError("give --config FILE, or --url URL and --nodes LIST", status=USAGE)
    if not given:
        serving = " and/or ".join(f"{flag.option} {flag.metavar}" for _, flag in flags)
        raise CliError(f"nothing to serve: give {serving}")
    return config_from_flags(
        url=args.url,
        nodes=args.nodes,
        protocol=args.protocol,
        stale_after_s=DEFAULT_STALE_AFTER_S if args.stale_after is None else args.stale_after,
        interval_s=0.5 if args.interval is None else args.interval,
        gateway_id=args.id,
        northbounds=given,
    )


def _check_requirements(config: GatewayConfig) -> None:
    """Exit 2 naming the extra, and the command that installs it here, when a configured
    northbound's library is missing (:mod:`._install`: a checkout's differs)."""
    for section in config.northbounds:
        spec = get_northbound(section)
        extra = northbound_extra(spec)
        for module in spec.requires:
            if importlib.util.find_spec(module) is None:
                raise CliError(
                    f"the gateway's {section} needs the {extra} extra ({module} is missing): "
                    + gateway_install_command(extra=extra)
                )


def run(args: argparse.Namespace) -> int:
    """Serve until SIGINT / SIGTERM; return 130 after SIGINT, 0 after SIGTERM."""
    if args.hash_password:
        return _hash_password()
    if args.new_token is not None:
        from ..gateway import valid_name

        if not valid_name(args.new_token):
            raise CliError(f"--new-token: a name of letters, digits, _ . -: {args.new_token!r}")
        return _new_token(args.new_token)
    if args.verbose:
        logging.basicConfig(
            level=logging.DEBUG if args.verbose > 1 else logging.INFO,
            format="%(asctime)s %(name)s %(levelname)s %(message)s",
        )
    if args.check_config is not None:
        return _check(args)
    config = _config(args)  # a bad one raises here: nothing has started
    _check_requirements(config)
    if args.decommission:
        from ._decommission import decommission

        return decommission(config)
    return asyncio.run(
        _serve(
            config,
            args.capture,
            demo=args.demo,
            tune_collector=args.tune_collector,
            path=args.config,
        )
    )


def _check(args: argparse.Namespace) -> int:
    """``--check-config FILE``: the start's checks, nothing opened (gateway._check)."""
    from ..gateway import GatewayStartError, check_config

    others = [
        option
        for option, given in (
            ("--config", args.config),
            ("--url", args.url),
            ("--nodes", args.nodes),
            ("--demo", args.demo),
            ("--id", args.id),
            ("--capture", args.capture),
            ("--decommission", args.decommission),
        )
        if given
    ]
    others += [flag.option for section, flag in _flags() if getattr(args, _dest(section))]
    if others:
        raise CliError(f"--check-config FILE checks that file alone: no {', '.join(others)}")
    config = load_config(args.check_config)  # the start's own reading: the same error
    _check_requirements(config)
    try:
        found = check_config(config, ports=args.port_check)
    except GatewayStartError as exc:
        raise CliError(str(exc)) from None
    except OSError as exc:
        raise CliError(_cannot_serve(exc)) from None
    print(f"{args.check_config}: the gateway would start")
    for line in found.summary:
        print(f"  {line}")
    for warning in found.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    return 0


def _ready(manager: ServiceManager, gateway: Gateway) -> None:
    """Every northbound listens: tell systemd, and keep its watchdog fed from the loop."""
    manager.ready(status_line(gateway))
    every = manager.ping_every_s
    if every is not None:
        gateway.loop_monitor.keep_alive(manager.alive, every)


def _cannot_serve(exc: OSError) -> str:
    """The one line of an error a start meets outside the northbounds (the audit log)."""
    where = f": {exc.filename}" if exc.filename else ""
    return f"cannot serve: {exc.strerror or exc}{where}"


async def _serve(
    config: GatewayConfig,
    capture: str | None,
    *,
    demo: bool = False,
    tune_collector: bool = True,
    path: str | None = None,
) -> int:
    from ..gateway import Gateway, GatewayStartError, ServiceManager

    manager = ServiceManager.from_environment()  # systemd's Type=notify (contrib/systemd)
    reloads = HangupReloads(path, manager)
    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    assert task is not None
    stop = asyncio.Event()
    status = 0
    starting = True

    def on_signal(sig: signal.Signals) -> None:
        nonlocal status
        if stop.is_set():  # a second signal: the first one's stop (and a lapse's stop) goes on
            return
        stop.set()
        status = EXIT_ON_SIGNAL[sig]
        if starting:  # a line's connection attempt may take seconds: give it up
            task.cancel()

    for sig in EXIT_ON_SIGNAL:
        loop.add_signal_handler(sig, on_signal, sig)
    loop.add_signal_handler(signal.SIGHUP, reloads.requested)
    try:
        async with Gateway(config, capture=capture, tune_collector=tune_collector) as gateway:
            starting = False
            for northbound in gateway.northbounds.values():
                line = northbound.announce()
                if line is not None:
                    print(line, flush=True)
            if manager is not None:
                _ready(manager, gateway)
            reloads.serving(gateway)
            simulated = [line.bus for line in gateway.lines if line.bus.simulator is not None]
            async with demo_running(simulated if demo else []):
                await stop.wait()
            await reloads.close()
            print("stopping", file=sys.stderr, flush=True)
            if manager is not None:
                manager.stopping()
    except asyncio.CancelledError:
        if not (starting and stop.is_set()):
            raise
        task.uncancel()  # ours: stopped while starting (nothing served, nothing written)
        print("stopping", file=sys.stderr, flush=True)
    except GatewayStartError as exc:  # a northbound's port in use...: which, where, why
        raise CliError(str(exc)) from None
    except OSError as exc:
        raise CliError(_cannot_serve(exc)) from None
    finally:
        for sig in (*EXIT_ON_SIGNAL, signal.SIGHUP):
            loop.remove_signal_handler(sig)
    return status
