"""``sj300 gateway --check-config``: what a start would refuse, found without starting.

A start refuses a configuration in three places: reading it
(:func:`~._config.load_config`: the TOML, the lines, grants, users, tokens,
limits, the files it names), the northbounds' libraries (the command line's
check of the extras), and starting (a northbound's port in use or its
address not on this host, a certificate that does not load, an audit log
that cannot be opened). The first two are the same functions a start calls;
this module does the third without starting anything:

- each address a northbound listens on is bound for an instant and closed,
  never listened on (no client can connect), the way the servers bind it
  (``SO_REUSEADDR``, every address the host name resolves to);
- each northbound's own files are loaded by its optional ``check`` hook
  (OPC UA: the certificate pair, or where a first start would write one);
- the audit log's file, or its directory, must be writable;
- no line is opened.

A problem is the :class:`~._errors.GatewayStartError` (or ``OSError``) a start
would raise, so the command line prints the same line. What a start does not
refuse (a serial port not there now: the line is served down and retried)
is a warning in the summary.

Checking beside the running gateway: its own ports are in use, so
``ports=False`` leaves them out (``--no-port-check``).
"""

from __future__ import annotations

import errno
import os
import socket
from dataclasses import dataclass, field
from pathlib import Path

from ..bus import parse_bus_url
from ._errors import GatewayStartError
from ._model import Endpoint, GatewayConfig, LineConfig
from ._northbound import get_northbound
from .recorder._settings import RecorderConfig

__all__ = ["ConfigCheck", "check_config", "check_recorder", "probe_endpoint"]


@dataclass(frozen=True, slots=True)
class ConfigCheck:
    """What the check found of a configuration that would start."""

    #: The summary, one line each (the gateway, each line, each northbound).
    summary: tuple[str, ...]
    #: What would not stop a start but will not work as it stands, one line each.
    warnings: tuple[str, ...] = field(default=())


def check_config(config: GatewayConfig, *, ports: bool = True) -> ConfigCheck:
    """Check *config* as a start would, opening nothing (module docstring).

    Raises:
        GatewayStartError: a northbound would not start (its port, its files).
        OSError: the audit log cannot be opened.
    """
    summary = [
        f"gateway {config.gateway_id}: {len(config.lines)} line(s), "
        f"{sum(len(line.nodes) for line in config.lines)} drive(s), "
        f"stale after {config.stale_after_s:g} s"
    ]
    warnings: list[str] = []
    for line in config.lines:
        summary.append(_line_summary(line))
        warning = _line_warning(line)
        if warning is not None:
            warnings.append(warning)
    for section, settings in config.northbounds.items():
        spec = get_northbound(section)
        endpoints = [endpoint for _, endpoint in spec.endpoints(settings)]
        if ports:
            for endpoint in endpoints:
                try:
                    probe_endpoint(endpoint)
                except OSError as exc:
                    raise GatewayStartError.of(section, [endpoint], exc) from None
        hook = getattr(spec, "check", None)
        notes = [] if hook is None else list(hook(settings))
        parts = [f"listens on {' and '.join(map(str, endpoints))}"] if endpoints else []
        summary.append(f"{section}: " + "; ".join([*parts, *notes] or ["configured"]))
    if config.audit_log is not None:
        _check_writable(config.audit_log)
        summary.append(f"audit log: {config.audit_log}")
    summary.append(check_recorder(config.recorder))
    return ConfigCheck(tuple(summary), tuple(warnings))


def check_recorder(recorder: RecorderConfig) -> str:
    """The recorder's summary line, its directory checked (it is made at the first record):
    what a start checks too.

    Raises:
        OSError: the directory is a file, or no directory can be made there.
    """
    if not recorder.enabled:
        return "recorder: off"
    where = "in memory" if recorder.directory is None else f"in {recorder.directory}"
    if recorder.directory is not None:
        directory = recorder.directory
        if directory.exists():
            if not directory.is_dir():
                raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), str(directory))
            _check_writable(directory / ".probe")
        else:
            nearest = next(p for p in directory.parents if p.exists())
            if not nearest.is_dir():
                raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), str(nearest))
            _check_writable(nearest / ".probe")
    return (
        f"recorder: trip records {where}, {recorder.before_s:g} s before and "
        f"{recorder.after_s:g} s after each, at most {recorder.max_records}"
    )


def probe_endpoint(endpoint: Endpoint) -> None:
    """Bind every address *endpoint* stands for, as a server would, and close at once.

    Raises:
        OSError: an address is in use, not on this host, or not ours to take.
    """
    infos = socket.getaddrinfo(
        endpoint.host, endpoint.port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
    )
    for family, kind, proto, _, address in infos:
        with socket.socket(family, kind, proto) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6:  # as asyncio's servers: v6 sockets only v6
                probe.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            probe.bind(address)


def _line_summary(line: LineConfig) -> str:
    grants = sum(len(grant.nodes) for grant in line.grants)
    writes = f", writes granted on {grants} drive(s)" if grants else ", read-only"
    return (
        f"line {line.name}: {line.protocol} on {line.url}, {len(line.nodes)} drive(s), "
        f"every {line.interval_s:g} s{writes}"
    )


def _line_warning(line: LineConfig) -> str | None:
    """A serial port or a capture that is not there now (a start serves the line down)."""
    address = parse_bus_url(line.url)
    if address.scheme not in ("serial", "replay") or "://" in address.device:
        return None  # a pyserial URL (socket://, rfc2217://) is reached only by opening it
    path = Path(address.device)
    if not path.is_absolute() and address.scheme == "serial":
        return None  # COM3, or a name pyserial resolves
    if not path.exists():
        problem = "does not exist now"
    elif not os.access(path, os.R_OK | os.W_OK):
        problem = "is not readable and writable by this user (the dialout group?)"
    else:
        return None
    return (
        f"line {line.name}: {path} {problem}: the gateway would start, serve the line "
        "as down and retry"
    )


def _check_writable(path: Path) -> None:
    """*path* can be appended to, or created (its nearest existing directory is writable)."""
    if path.exists():
        if path.is_dir():
            raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(path))
        if not os.access(path, os.W_OK):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return
    parent = path.parent
    if parent.exists() and not parent.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), str(path))
    if not parent.exists():
        raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), str(path))
    if not os.access(parent, os.W_OK | os.X_OK):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
