"""Argument types shared by the subcommands: node lists and listen addresses.

Each raises :class:`argparse.ArgumentTypeError` with a message that fits on
one line, which the parser prints as the whole error.
"""

from __future__ import annotations

import argparse
import ipaddress
from dataclasses import dataclass
from typing import Final
from urllib.parse import urlsplit

from ..bus import format_node_list, parse_node_list
from ..wire import LocalProtocolError

__all__ = ["ListenAddress", "format_nodes", "parse_any_nodes", "parse_listen", "parse_nodes"]

#: Where ``simulate`` listens when given nothing: loopback, the device-server port 4001.
DEFAULT_PORT: Final = 4001
LOOPBACK: Final = "127.0.0.1"


def parse_nodes(text: str) -> list[int]:
    """``"1-8,12,20-22"`` -> sorted node numbers; each 1..32, repeats allowed and merged."""
    try:
        return list(parse_node_list(text))
    except LocalProtocolError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def parse_any_nodes(text: str) -> list[int]:
    """Like :func:`parse_nodes`, but 0..32: SJ300 nodes or FR-700 stations (the bus checks)."""
    try:
        return list(parse_node_list(text, low=0, high=32))
    except LocalProtocolError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def format_nodes(nodes: list[int]) -> str:
    """The inverse of :func:`parse_nodes`, compact: ``[1, 2, 3, 5]`` -> ``"1-3,5"``."""
    return format_node_list(tuple(sorted(set(nodes))))


@dataclass(frozen=True, slots=True)
class ListenAddress:
    """Where a TCP server listens."""

    host: str
    port: int

    @property
    def is_loopback(self) -> bool:
        """True for 127.0.0.0/8, ::1 and "localhost"."""
        if self.host == "localhost":
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return False

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"tcp://{host}:{self.port}"


def parse_listen(text: str) -> ListenAddress:
    """``tcp://HOST:PORT`` -> address. No host means loopback, no port means 4001.

    Only a host written out listens beyond this machine: ``tcp://:4001``
    stays on loopback, ``tcp://0.0.0.0:4001`` is the explicit way out.
    """
    if "://" not in text:
        raise argparse.ArgumentTypeError(f"bad listen address {text!r}: use tcp://HOST:PORT")
    parts = urlsplit(text)
    if parts.scheme != "tcp":
        raise argparse.ArgumentTypeError(
            f"bad listen address {text!r}: only tcp:// is supported (use --pty for a pty)"
        )
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise argparse.ArgumentTypeError(f"bad listen address {text!r}: use tcp://HOST:PORT")
    try:
        port = parts.port
    except ValueError:
        raise argparse.ArgumentTypeError(f"bad listen address {text!r}: bad port") from None
    return ListenAddress(parts.hostname or LOOPBACK, DEFAULT_PORT if port is None else port)
