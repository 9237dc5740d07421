"""Bus URLs: which transport, where, and with which line settings.

Forms::

    tcp://HOST:PORT[?baudrate=19200&bytesize=8&parity=N&stopbits=1]
        raw TCP to a serial device server; the query describes the RS-485 line
        behind it (used for wire-time arithmetic only)
    rfc2217://HOST:PORT[?baudrate=19200&bytesize=8&parity=N&stopbits=1]
        a serial port on an RFC 2217 server (ser2net's telnet(rfc2217), a
        Moxa NPort...): the query's settings are set on the server's port
        when the bus connects (19200 8N1 when none are given)
    serial:///dev/ttyUSB0?baudrate=19200&bytesize=8&parity=E&stopbits=1
    /dev/ttyUSB0, COM3                  a bare device path: serial, default settings
    replay://PATH.pcapng[?interface=N]
        a capture played back: each request the host writes is answered with
        what the capture recorded after it (the protocol and line settings
        come from the capture; see :mod:`sj300_async.transports._replay`)
    sim://?nodes=1-8[&wait_ms=0&factory_defaults=1&pace=1&baudrate=19200...]
        the in-memory simulator: an instant line unless a baud rate is
        given; with one, replies arrive no sooner than that line could carry
        them (pace=1 also paces every character)

Common query options: ``echo=auto|1|0`` for the RS-485 adapter's local
echo (``auto``, the default, detects and strips it; ``1`` says the line
echoes; ``0`` never looks: see :mod:`._protocol`); ``protocol=NAME`` picks
the protocol (``sj300``, the default, or ``fr700``; see :mod:`._registry`).
Each protocol adds its own options (its dialect's ``url_options``), e.g.
FR-700's ``wait_field``, ``terminator`` and ``ack``. A ``sim://`` bus
simulates the protocol's default nodes unless ``nodes=`` says otherwise.
Any other query key is refused, so a typo cannot be silently ignored, and
one protocol's options on another's bus are refused too.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final, Literal
from urllib.parse import parse_qsl, urlsplit

from ..wire import LineSettings, LocalProtocolError
from ._registry import DEFAULT_PROTOCOL, get_dialect, protocol_names

__all__ = ["BusAddress", "parse_bus_url", "parse_node_list", "url_protocol"]

Scheme = Literal["tcp", "rfc2217", "serial", "sim", "replay"]

_LINE_KEYS: Final = ("baudrate", "bytesize", "parity", "stopbits")
_COMMON_KEYS: Final = frozenset((*_LINE_KEYS, "echo", "protocol"))
_SIM_KEYS: Final = frozenset(("nodes", "wait_ms", "factory_defaults", "pace"))
_REPLAY_KEYS: Final = frozenset(("interface",))
_SCHEMES: Final = ("tcp", "rfc2217", "serial", "sim", "replay")
_SCHEME_KEYS: Final = {"sim": _SIM_KEYS, "replay": _REPLAY_KEYS}
_TRUE: Final = frozenset(("1", "true", "yes", "on"))
_FALSE: Final = frozenset(("0", "false", "no", "off", ""))


@dataclass(frozen=True, slots=True)
class BusAddress:
    """A parsed bus URL."""

    scheme: Scheme
    #: tcp, rfc2217: host and port.
    host: str = ""
    port: int = 0
    #: serial: device path or pyserial URL; replay: the capture's path.
    device: str = ""
    #: Line settings given in the URL (None: the transport's default).
    line: LineSettings | None = None
    #: Local echo: True strip it (``echo=1``), False never look (``echo=0``),
    #: None detect it (``echo=auto``, or not given).
    echo: bool | None = None
    #: sim: the simulated nodes and options.
    nodes: tuple[int, ...] = ()
    sim_options: dict[str, str] = field(default_factory=dict)
    #: The protocol named in the URL or by the caller (None: not given, the default).
    protocol: str | None = None
    #: The protocol's own URL options as given (e.g. FR-700's ``terminator``).
    protocol_options: dict[str, str] = field(default_factory=dict)

    @property
    def description(self) -> str:
        """Short human-readable form for messages."""
        if self.scheme in ("tcp", "rfc2217"):
            return f"{self.scheme}://{self.host}:{self.port}"
        if self.scheme == "serial":
            return f"serial://{self.device}"
        if self.scheme == "replay":
            return f"replay://{self.device}"
        noun = get_dialect(self.protocol or DEFAULT_PROTOCOL).node_noun
        return f"sim://({noun}s {format_node_list(self.nodes)})"


def parse_node_list(
    text: str, *, low: int = 1, high: int = 32, noun: str = "node"
) -> tuple[int, ...]:
    """Parse ``"1-8,12,20-22"`` into sorted unique node numbers *low*..*high* (default 1..32).

    *noun* is what the protocol calls an address, for the messages (``"station"``).

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
                f"bad {noun} list {text!r}: {noun}s are {low}..{high}, got {part!r}"
            )
        nodes.update(range(lo, hi + 1))
    if not nodes:
        raise LocalProtocolError(f"bad {noun} list {text!r}: no {noun}s")
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


def _parse_echo(value: str) -> bool | None:
    """``echo=``: ``auto`` (None), or a boolean flag."""
    if value.lower() == "auto":
        return None
    try:
        return parse_flag("echo", value)
    except LocalProtocolError:
        raise LocalProtocolError(f"echo must be auto, 1 or 0, got {value!r}") from None


def url_protocol(url: str) -> str | None:
    """The protocol a bus URL's query names (``protocol=``, lower-cased), or None.

    Only that key is read, as :func:`parse_bus_url` reads it; the rest of the
    URL is not checked (a URL :func:`parse_bus_url` refuses may give None).
    """
    if not isinstance(url, str) or "://" not in url:
        return None
    try:
        query = urlsplit(url.strip()).query
    except ValueError:
        return None
    named = dict(parse_qsl(query, keep_blank_values=True)).get("protocol")
    return None if named is None else named.lower()


def parse_bus_url(url: str, *, protocol: str | None = None) -> BusAddress:
    """Parse a bus URL (see the module docstring).

    Args:
        protocol: the protocol when the URL does not name one (``open_bus``'s
            argument); it sets the range of ``sim://`` nodes and the
            protocol options the URL may carry.

    Raises:
        LocalProtocolError: unknown scheme, missing host/port/device, unknown
            query key, a line setting the protocol does not allow, or a
            *protocol* other than the URL's.
    """
    if not isinstance(url, str) or not url.strip():
        raise LocalProtocolError(f"bus URL must be a non-empty string, got {url!r}")
    url = url.strip()
    if protocol is not None:
        get_dialect(protocol)  # an unknown name is refused here
    if "://" not in url:
        return BusAddress("serial", device=url, line=LineSettings(), protocol=protocol)
    try:
        parts = urlsplit(url)
    except ValueError as exc:  # e.g. "Invalid IPv6 URL"
        raise LocalProtocolError(f"bad bus URL {url!r}: {exc}") from None
    scheme = parts.scheme.lower()
    if scheme not in _SCHEMES:
        raise LocalProtocolError(
            f"unknown bus URL scheme {parts.scheme!r} in {url!r} "
            f"(use {', '.join(name + '://' for name in _SCHEMES)})"
        )
    query = dict(parse_qsl(parts.query, keep_blank_values=True))
    named = query.pop("protocol", None)
    if named is not None:
        named = named.lower()
        if named not in protocol_names():
            raise LocalProtocolError(
                f"unknown protocol {named!r} in {url!r} (use {' or '.join(protocol_names())})"
            )
        if protocol is not None and named != protocol:
            raise LocalProtocolError(f"protocol={protocol!r} but the URL says protocol={named}")
    protocol = named or protocol
    dialect = get_dialect(protocol or DEFAULT_PROTOCOL)
    allowed = _COMMON_KEYS | dialect.url_options | _SCHEME_KEYS.get(scheme, frozenset())
    unknown = set(query) - allowed
    if unknown:
        raise LocalProtocolError(_unknown_options(url, unknown, allowed))
    line = None
    if any(k in query for k in _LINE_KEYS):
        line = LineSettings.parse(
            query.get("baudrate", "19200"),
            query.get("bytesize", "8"),
            query.get("parity", "N"),
            query.get("stopbits", "1"),
        )
    echo = _parse_echo(query["echo"]) if "echo" in query else None
    protocol_options = {k: v for k, v in query.items() if k in dialect.url_options}
    if scheme in ("tcp", "rfc2217"):
        try:
            host, port = parts.hostname, parts.port
        except ValueError as exc:
            raise LocalProtocolError(f"bad port in {url!r}: {exc}") from None
        if port == 0:
            raise LocalProtocolError(f"{scheme} URL needs a port 1..65535, got 0: {url!r}")
        if not host or port is None:
            raise LocalProtocolError(f"{scheme} URL needs a host and a port: {url!r}")
        return BusAddress(
            "rfc2217" if scheme == "rfc2217" else "tcp",
            host=host,
            port=port,
            # RFC 2217 sets the line on the server, so it always has settings to send.
            line=(line or LineSettings()) if scheme == "rfc2217" else line,
            echo=echo,
            protocol=protocol,
            protocol_options=protocol_options,
        )
    if scheme == "replay":
        path = parts.netloc + parts.path
        if not path:
            raise LocalProtocolError(f"replay URL needs a capture file: {url!r}")
        return BusAddress(
            "replay",
            device=path,
            line=line,
            echo=echo,
            protocol=protocol,
            protocol_options=protocol_options,
            sim_options={k: v for k, v in query.items() if k in _REPLAY_KEYS},
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
    low, high = dialect.node_range
    nodes = parse_node_list(
        query.pop("nodes", dialect.default_sim_nodes), low=low, high=high, noun=dialect.node_noun
    )
    return BusAddress(
        "sim",
        line=line,
        echo=echo,
        nodes=nodes,
        sim_options={k: v for k, v in query.items() if k in _SIM_KEYS},
        protocol=protocol,
        protocol_options=protocol_options,
    )


def _unknown_options(url: str, unknown: set[str], allowed: frozenset[str]) -> str:
    """The message for query keys the URL's protocol does not know: whose options are they?"""
    for name in protocol_names():
        theirs = unknown & get_dialect(name).url_options
        if theirs:
            return (
                f"{', '.join(sorted(theirs))} in {url!r} are options of protocol {name}: "
                f"add protocol={name}"
            )
    return (
        f"unknown option(s) {', '.join(sorted(unknown))} in {url!r}; "
        f"allowed: {', '.join(sorted(allowed))}"
    )
