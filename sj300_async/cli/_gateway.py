"""``sj300 gateway``: own the lines, poll the drives, serve Modbus TCP and metrics until stopped.

``--config gateway.toml`` describes everything (several lines, write
grants, leases; docs/GATEWAY.md); the flags cover the simple case, one
read-only line: ``--url URL --nodes LIST [--protocol fr700] --modbus
HOST:PORT --metrics HOST:PORT --mqtt mqtt://HOST:PORT --id NAME``. A bad
configuration starts nothing (exit 2, one line naming the file, line and
key).

stdout carries one line per server, ``modbus on 127.0.0.1:1502``,
``metrics on http://127.0.0.1:9300/metrics`` and ``mqtt to
mqtt://127.0.0.1:1883 as gw1`` (the broker is connected to in the
background: the line says where, not that it answered), flushed at once so
that a script can read the real port when it asked for port 0. SIGINT and SIGTERM
stop it cleanly (docs/GATEWAY.md: the order, and the one command it may
send on the way out); exit status 0.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys
from typing import Any

from ._errors import USAGE, CliError

__all__ = ["add_parser"]


def add_parser(subparsers: Any) -> None:
    """Add ``gateway`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "gateway",
        help="own the lines and serve the drives over Modbus TCP, with Prometheus metrics",
        description="Own one or more RS-485 lines, poll their drives and serve them: "
        "Modbus TCP for SCADA (a unit id per drive), /metrics and /healthz over HTTP. "
        "Read-only unless the --config file grants writes. Needs the gateway extra.",
    )
    p.add_argument("--config", metavar="FILE", help="the gateway's TOML configuration")
    # Its own --url and --protocol: the bus options of other commands (--timeout,
    # --trace...) do not apply to a process that owns several lines.
    p.add_argument("--url", default=None, help="the one line's bus URL (without --config)")
    p.add_argument(
        "--protocol", default=None, help="with --url: the line's protocol (sj300, fr700)"
    )
    p.add_argument("--nodes", metavar="LIST", help="with --url: the drives to poll, e.g. 1-8")
    p.add_argument("--modbus", metavar="HOST:PORT", help="serve Modbus TCP there (port 0: any)")
    p.add_argument("--metrics", metavar="HOST:PORT", help="serve /metrics and /healthz there")
    p.add_argument(
        "--mqtt",
        metavar="URL",
        help="publish to this MQTT broker (mqtt://HOST[:PORT] or mqtts://): state, "
        "availability, Home Assistant discovery",
    )
    p.add_argument(
        "--id", metavar="NAME", help="the gateway's name on MQTT (default: the host name)"
    )
    p.add_argument(
        "--stale-after",
        type=float,
        default=None,
        metavar="S",
        help="with --url: refuse reads of data older than this (default 5 s)",
    )
    p.add_argument("--interval", type=float, default=None, metavar="S", help="poll interval")
    p.add_argument(
        "--capture",
        metavar="PATH",
        help="write every line's frames to PATH, a pcapng file (one interface per line)",
    )
    p.add_argument("-v", "--verbose", action="count", default=0, help="log more (-vv: debug)")
    p.set_defaults(run=run)


def _config(args: argparse.Namespace) -> Any:
    from ..gateway._config import config_from_flags, load_config
    from ..gateway._model import DEFAULT_STALE_AFTER_S

    if args.config is not None:
        if args.url or args.nodes or args.modbus or args.metrics or args.mqtt or args.id:
            raise CliError(
                "--config describes everything: "
                "no --url, --nodes, --modbus, --metrics, --mqtt, --id"
            )
        return load_config(args.config)
    if not args.url or not args.nodes:
        raise CliError("give --config FILE, or --url URL and --nodes LIST", status=USAGE)
    if not args.modbus and not args.metrics and not args.mqtt:
        raise CliError(
            "nothing to serve: give --modbus HOST:PORT, --metrics HOST:PORT and/or --mqtt URL"
        )
    return config_from_flags(
        url=args.url,
        nodes=args.nodes,
        protocol=args.protocol,
        modbus=args.modbus,
        metrics=args.metrics,
        stale_after_s=DEFAULT_STALE_AFTER_S if args.stale_after is None else args.stale_after,
        interval_s=0.5 if args.interval is None else args.interval,
        mqtt=args.mqtt,
        gateway_id=args.id,
    )


def run(args: argparse.Namespace) -> int:
    """Serve until SIGINT / SIGTERM; return 0."""
    try:
        import aiomqtt  # noqa: F401
        import prometheus_client  # noqa: F401
        import pymodbus  # noqa: F401
    except ImportError as exc:
        raise CliError(
            f"the gateway needs the gateway extra ({exc.name} is missing): "
            "pip install 'sj300-async[gateway]'"
        ) from None
    if args.verbose:
        logging.basicConfig(
            level=logging.DEBUG if args.verbose > 1 else logging.INFO,
            format="%(asctime)s %(name)s %(levelname)s %(message)s",
        )
    config = _config(args)  # a bad one raises here: nothing has started
    return asyncio.run(_serve(config, args.capture))


async def _serve(config: Any, capture: str | None) -> int:
    from ..gateway._gateway import Gateway

    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    try:
        async with Gateway(config, capture=capture) as gateway:
            if gateway.modbus is not None:
                host = config.modbus.host
                print(f"modbus on {host}:{gateway.modbus.port}", flush=True)
            if gateway.http is not None:
                port = gateway.http.sockets[0].getsockname()[1]
                print(f"metrics on http://{config.metrics.host}:{port}/metrics", flush=True)
            if config.mqtt is not None:
                print(f"mqtt to {config.mqtt.url} as {config.gateway_id}", flush=True)
            await stop.wait()
            print("stopping", file=sys.stderr, flush=True)
    except OSError as exc:
        raise CliError(f"cannot serve: {exc.strerror or exc}") from None
    return 0
