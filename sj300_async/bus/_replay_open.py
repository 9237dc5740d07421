"""Opening ``replay://PATH``: the capture says which protocol and which line.

The interface's link type names the protocol (each dialect's
``capture_linktype``), its description the line settings
(``"sj300 19200 8N1"``, written by :func:`._capture.describe_line`), so a
replayed bus times its requests as the captured one did. A capture of
several lines (the gateway's) needs ``?interface=N``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Final

from ..transports import ReplayScript
from ..wire import (
    INSTANT_LINE,
    LineSettings,
    LocalProtocolError,
    PcapngCapture,
    PcapngInterface,
    read_pcapng,
)
from ._dialect import Dialect
from ._registry import get_dialect, protocol_names
from ._url import BusAddress

__all__ = ["ReplaySetup", "open_replay"]

_LINE: Final = re.compile(r"(\d+) ([5-8])([NEO])([12])\Z")


class ReplaySetup:
    """What a replayed bus needs: the script, the protocol's name, the line."""

    def __init__(self, script: ReplayScript, protocol: str, line: LineSettings) -> None:
        self.script = script
        self.protocol = protocol
        self.line = line


def _protocol_of(interface: PcapngInterface, path: str) -> str:
    for name in protocol_names():
        if get_dialect(name).capture_linktype == interface.linktype:
            return name
    raise LocalProtocolError(
        f"{path}: link type {interface.linktype} is no protocol of ours "
        f"({', '.join(f'{get_dialect(n).capture_linktype} {n}' for n in protocol_names())})"
    )


def _line_of(interface: PcapngInterface) -> LineSettings:
    """The line the description names; else the interface's speed at 8N1; else instant."""
    _, _, settings = interface.description.partition(" ")
    if settings == "instant":
        return INSTANT_LINE
    found = _LINE.match(settings)
    if found:
        return LineSettings.parse(*found.groups())
    if interface.speed:
        return LineSettings.parse(str(interface.speed), "8", "N", "1")
    return INSTANT_LINE


def _pick(capture: PcapngCapture, address: BusAddress, path: str) -> int:
    listed = "; ".join(
        f"{n}: {i.name or '?'} ({i.description or i.linktype})"
        for n, i in enumerate(capture.interfaces)
    )
    text = address.sim_options.get("interface")
    if text is None:
        if len(capture.interfaces) == 1:
            return 0
        raise LocalProtocolError(f"{path} holds several lines: add ?interface=N ({listed})")
    try:
        number = int(text)
    except ValueError:
        raise LocalProtocolError(f"interface must be a number, got {text!r}") from None
    if not 0 <= number < len(capture.interfaces):
        raise LocalProtocolError(f"{path} has no interface {number} ({listed})")
    return number


def open_replay(address: BusAddress, protocol: str | None) -> ReplaySetup:
    """Read the capture of a ``replay://`` URL and set its replay up.

    Raises:
        LocalProtocolError: the file cannot be read or is no capture of ours,
            or it disagrees with the protocol the caller named.
    """
    path = address.device
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise LocalProtocolError(f"cannot read capture {path}: {exc.strerror or exc}") from None
    capture = read_pcapng(data)
    if not capture.interfaces:
        raise LocalProtocolError(f"{path}: the capture describes no line")
    number = _pick(capture, address, path)
    interface = capture.interfaces[number]
    name = _protocol_of(interface, path)
    wanted = protocol or address.protocol
    if wanted is not None and wanted != name:
        raise LocalProtocolError(
            f"{path} is a capture of {name}, not {wanted}: pass protocol={name!r}"
        )
    dialect: Dialect[Any, Any] = get_dialect(name).configure(address.protocol_options)
    framer = dialect.line_framer()
    script = ReplayScript(
        capture,
        number,
        name=address.description,
        describe=lambda frame: framer.classify(frame, outbound=True).summary,
    )
    return ReplaySetup(script, name, _line_of(interface))
