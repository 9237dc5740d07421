"""Bus URLs: which transport, where, and with which line settings.

Forms::

    tcp://HOST:PORT[?baudrate=19200&bytesize=8&parity=N&stopbits=1]
        raw TCP to a serial device server; the query describes the RS-485 line
        behind it (used for wire-time arithmetic only)
    serial:///dev/ttyUSB0?baudrate=19200&bytesize=8&parity=E&stopbits=1
    /dev/ttyUSB0, COM3                  a bare device path: serial, default settings
    sim://?nodes=1-8[&wait_ms=0&factory_defaults=1&pace=1&baudrate=19200...]
        the in-memory simulator (an instant line unless pace=1)

Common query options: ``echo=1`` strips the RS-485 adapter's local echo;
``protocol=sj300`` (the default) or ``protocol=fr700`` picks the protocol.
FR-700 line options: ``wait_field=1`` (requests carry the waiting-time
character; default on, the drive's factory setting), ``terminator=cr``
(``none``, ``cr`` or ``crlf``; default ``cr``), ``ack=0`` (send ACK after
read data). On an FR-700 ``sim://`` bus the nodes are stations 0..31
(default ``0-7``). Any other query key is refused, so a typo cannot be
silently ignored, and FR-700 options on an SJ300 bus are refused too.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final, Literal
from urllib.parse import parse_qsl, urlsplit

from ._constants import MAX_NODE, MIN_NODE
from ._errors import LocalProtocolError
from ._line import LineSettings

__all__ = ["NODE_RANGES", "PROTOCOLS", "BusAddress", "parse_bus_url", "parse_node_list"]

Scheme = Literal["tcp", "serial", "sim"]
ProtocolName = Literal["sj300", "fr700"]

#: The protocols a bus can speak.
PROTOCOLS: Final[tuple[ProtocolName, ...]] = ("sj300", "fr700")
_LINE_KEYS: Final = ("baudrate", "bytesize", "parity", "stopbits")
#: Query keys that configure the FR-700 dialect.
FR700_KEYS: Final = ("wait_field", "terminator", "ack")
_COMMON_KEYS: Final = (*_LINE_KEYS, "echo", "protocol", *FR700_KEYS)
_ALLOWED_KEYS: Final[dict[str, frozenset[str]]] = {
    "tcp": frozenset(_COMMON_KEYS),
    "serial": frozenset(_COMMON_KEYS),
    "sim": frozenset((*_COMMON_KEYS, "nodes", "wait_ms", "factory_defaults", "pace")),
}
#: The node numbers of each protocol: SJ300 nodes 1..32, FR-700 stations 0..31.
NODE_RANGES: Final[dict[str, tuple[int, int]]] = {"sj300": (MIN_NODE, MAX_NODE), "fr700": (0, 31)}
_DEFAULT_SIM_NODES: Final = {"sj300": "1-8", "fr700": "0-7"}
_TRUE: Final = frozenset(("1", "true", "yes", "on"))
_FALSE: Final = frozenset(("0", "false", "no", "off", ""))


@dataclass(frozen=True, slots=True)
class BusAddress:
    """A parsed bus URL."""

    scheme: Scheme
    #: tcp: host and port.
    host: str = ""
    port: int = 0
    #: serial: device path or pyserial URL.
    device: str = ""
    #: Line settings given in the URL (None: the transport's default).
    line: LineSettings | None = None
    #: Strip local echo (None: not given).
    echo: bool | None = None
    #: sim: the simulated nodes and options.
    nodes: tuple[int, ...] = ()
    sim_options: dict[str, str] = field(default_factory=dict)
    #: The protocol named in the URL (None: not given, SJ300 unless told otherwise).
    protocol: ProtocolName | None = None
    #: FR-700 line options as given (``wait_field``, ``terminator``, ``ack``).
    protocol_options: dict[str, str] = field(default_factory=dict)

    @property
    def description(self) -> str:
        """Short human-readable form for messages."""
        if self.scheme == "tcp":
            return f"tcp://{self.host}:{self.port}"
        if self.scheme == "serial":
            return f"serial://{self.device}"
        what = "stations" if self.protocol == "fr700" else "nodes"
        return f"sim://({what} {format_node_list(self.nodes)})"


def parse_node_list(text: str, *, low: int = MIN_NODE, high: int = MAX_NODE) -> tuple[int, ...]:
    """Parse ``"1-8,12,20-22"`` into sorted unique node numbers *low*..*high* (1..32).

    Raises:
        LocalProtocolError: malformed, empty, or a node outside *low*..*high*.
    """
    nodes: set[int] = set()
    for part in text.replace(" ", "").split(","):
        if not part:
            continue
        lo_text, sep, hi_text = part.partition("-")
        try:
            lo = int(lo_text)
            hi = int(hi_text) if sep else lo
        except ValueError:
            raise LocalProtocolError(f"bad node list {text!r}: {part!r} is not N or N-M") from None
        if lo > hi:
            raise LocalProtocolError(f"bad node list {text!r}: range {part!r} runs backwards")
        if not (lo >= low and hi <= high):
            raise LocalProtocolError(
                f"bad node list {text!r}: nodes are {low}..{high}, got {part!r}"
            )
        nodes.update(range(lo, hi + 1))
    if not nodes:
        raise LocalProtocolError(f"bad node list {text!r}: no nodes")
    return tuple(sorted(nodes))


def format_node_list(nodes: tuple[int, ...]) -> str:
    """Inverse of :func:`parse_node_list` (``(1, 2, 3, 5)`` → ``"1-3,5"``)."""
    parts: list[str] = []
    for n in nodes:
        if parts and parts[-1].split("-")[-1] == str(n - 1):
            parts[-1] = f"{parts[-1].split('-')[0]}-{n}"
        else:
            parts.append(str(n))
    return ",".join(parts)


def parse_flag(key: str, value: str) -> bool:
    """Parse a boolean query value.

    Raises:
        LocalProtocolError: not one of 1/0, true/false, yes/no, on/off.
    """
    lowered = value.lower()
    if lowered in _TRUE:
        return True
    if lowered in _FALSE:
        return False
    raise LocalProtocolError(f"{key} must be true or false, got {value!r}")


def parse_bus_url(url: str, *, protocol: ProtocolName | None = None) -> BusAddress:
    """Parse a bus URL (see the module docstring).

    Args:
        protocol: the protocol when the URL does not name one (``open_bus``'s
            argument); it sets the range of ``sim://`` nodes and allows the
            FR-700 options.

    Raises:
        LocalProtocolError: unknown scheme, missing host/port/device, unknown
            query key, a line setting the protocol does not allow, or a
            *protocol* other than the URL's.
    """
    if not isinstance(url, str) or not url.strip():
        raise LocalProtocolError(f"bus URL must be a non-empty string, got {url!r}")
    url = url.strip()
    if "://" not in url:
        return BusAddress("serial", device=url, line=LineSettings())
    try:
        parts = urlsplit(url)
    except ValueError as exc:  # e.g. "Invalid IPv6 URL"
        raise LocalProtocolError(f"bad bus URL {url!r}: {exc}") from None
    scheme = parts.scheme.lower()
    if scheme not in _ALLOWED_KEYS:
        raise LocalProtocolError(
            f"unknown bus URL scheme {parts.scheme!r} in {url!r} (use tcp://, serial:// or sim://)"
        )
    query = dict(parse_qsl(parts.query, keep_blank_values=True))
    unknown = set(query) - _ALLOWED_KEYS[scheme]
    if unknown:
        raise LocalProtocolError(
            f"unknown option(s) {', '.join(sorted(unknown))} in {url!r}; "
            f"allowed: {', '.join(sorted(_ALLOWED_KEYS[scheme]))}"
        )
    line = None
    if any(k in query for k in _LINE_KEYS):
        line = LineSettings.parse(
            query.get("baudrate", "19200"),
            query.get("bytesize", "8"),
            query.get("parity", "N"),
            query.get("stopbits", "1"),
        )
    echo = parse_flag("echo", query["echo"]) if "echo" in query else None
    named = _protocol(query.pop("protocol", None), url)
    if protocol is not None and protocol not in PROTOCOLS:
        raise LocalProtocolError(f"unknown protocol {protocol!r} (use {' or '.join(PROTOCOLS)})")
    if named is not None and protocol is not None and named != protocol:
        raise LocalProtocolError(f"protocol={protocol!r} but the URL says protocol={named}")
    protocol = named or protocol
    protocol_options: dict[str, str] = {k: query.pop(k) for k in FR700_KEYS if k in query}
    if protocol_options and protocol != "fr700":
        raise LocalProtocolError(
            f"{', '.join(sorted(protocol_options))} in {url!r} are FR-700 options: "
            f"add protocol=fr700"
        )
    if scheme == "tcp":
        try:
            host, port = parts.hostname, parts.port
        except ValueError as exc:
            raise LocalProtocolError(f"bad port in {url!r}: {exc}") from None
        if port == 0:
            raise LocalProtocolError(f"tcp URL needs a port 1..65535, got 0: {url!r}")
        if not host or port is None:
            raise LocalProtocolError(f"tcp URL needs a host and a port: {url!r}")
        return BusAddress(
            "tcp",
            host=host,
            port=port,
            line=line,
            echo=echo,
            protocol=protocol,
            protocol_options=protocol_options,
        )
    if scheme == "serial":
        device = parts.netloc + parts.path
        if not device:
            raise LocalProtocolError(f"serial URL needs a device path: {url!r}")
        return BusAddress(
            "serial",
            device=device,
            line=line or LineSettings(),
            echo=echo,
            protocol=protocol,
            protocol_options=protocol_options,
        )
    kind = protocol or "sj300"
    low, high = NODE_RANGES[kind]
    nodes = parse_node_list(query.pop("nodes", _DEFAULT_SIM_NODES[kind]), low=low, high=high)
    options = {k: v for k, v in query.items() if k in ("wait_ms", "factory_defaults", "pace")}
    return BusAddress(
        "sim",
        line=line,
        echo=echo,
        nodes=nodes,
        sim_options=options,
        protocol=protocol,
        protocol_options=protocol_options,
    )


def _protocol(value: str | None, url: str) -> ProtocolName | None:
    if value is None:
        return None
    lowered = value.lower()
    for protocol in PROTOCOLS:
        if lowered == protocol:
            return protocol
    raise LocalProtocolError(
        f"unknown protocol {value!r} in {url!r} (use {' or '.join(PROTOCOLS)})"
    )
