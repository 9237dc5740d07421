"""Telnet (RFC 854) and its COM-PORT-OPTION (RFC 2217), sans-IO: the client's side of the wire.

An RFC 2217 access server (ser2net's ``telnet(rfc2217)`` accepter, a Moxa
NPort in RFC 2217 mode) speaks telnet on its TCP port: the serial bytes
travel as telnet data, 0xFF (IAC) doubled, and the line settings travel as
subnegotiations of option 44. :class:`TelnetCodec` separates the two. No
sockets, no asyncio (an import-linter contract and a test scan prove it);
the asyncio transport around it is :mod:`._rfc2217`. Its contract, in three
calls as h11's:

- :meth:`TelnetCodec.feed` takes bytes from the server and returns events:
  :class:`Payload` (serial bytes, IAC-unescaped), :class:`OptionChanged`,
  :class:`ComPortReply`, :class:`LineStateChanged`,
  :class:`ModemStateChanged`, :class:`FlowControl`, :class:`Signature`,
  :class:`SignatureRequested`, :class:`TelnetCommand` and
  :class:`BadSubnegotiation`. Nothing the server
  sends is dropped without an event.
- :meth:`TelnetCodec.data_to_send` returns what the codec owes the server:
  the answers to its option requests, a signature it asked for.
- :func:`escape`, :meth:`TelnetCodec.request`, :func:`com_port_command`
  make what the client sends of its own accord.

The receiver is a small explicit state machine over :class:`_Rx`::

    DATA --IAC--> IAC --IAC--> DATA (a literal 0xFF)
                  IAC --WILL/WONT/DO/DONT--> VERB --option--> DATA
                  IAC --SB--> SB --option--> SB_DATA --IAC--> SB_IAC
                  IAC --other command--> DATA (a TelnetCommand event)
    SB_IAC --IAC--> SB_DATA (a literal 0xFF)   SB_IAC --SE--> DATA
    SB_IAC --other--> IAC (the subnegotiation was cut short: BadSubnegotiation)

Its state lives across calls, so a sequence split anywhere between two
chunks decodes as if it had come whole.

Option negotiation follows RFC 1143's "Q method" without its queue (the
client never changes its mind while a request is pending): each option
has a state on each side, and every transition is in :data:`_TRANSITIONS`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Final

from ..wire import LineSettings, RemoteProtocolError

__all__ = [
    "BadSubnegotiation",
    "ComPortCommand",
    "ComPortReply",
    "FlowControl",
    "LineState",
    "LineStateChanged",
    "ModemState",
    "ModemStateChanged",
    "OptState",
    "OptionChanged",
    "Payload",
    "Side",
    "Signature",
    "SignatureRequested",
    "TelnetCodec",
    "TelnetCommand",
    "TelnetError",
    "TelnetEvent",
    "com_port_command",
    "escape",
    "line_commands",
]

# Telnet commands (RFC 854).
IAC: Final = 255
DONT: Final = 254
DO: Final = 253
WONT: Final = 252
WILL: Final = 251
SB: Final = 250
SE: Final = 240

# Options.
BINARY: Final = 0  #: RFC 856: 8-bit data, no CR NUL stuffing
ECHO: Final = 1  #: RFC 857 (ser2net offers it; a serial line must not echo)
SGA: Final = 3  #: RFC 858: suppress go-ahead
COM_PORT: Final = 44  #: RFC 2217

_IAC_BYTE: Final = b"\xff"
_IAC_IAC: Final = b"\xff\xff"
#: The longest subnegotiation kept (a signature is the longest RFC 2217 has):
#: going over is the server's error, not something to buffer without end.
MAX_SUBNEGOTIATION: Final = 1024
#: What the client says when the server asks for its signature.
CLIENT_SIGNATURE: Final = b"sj300_async"
#: The server's replies carry the client's command code plus this.
SERVER_OFFSET: Final = 100


class TelnetError(RemoteProtocolError):
    """The server broke telnet's rules beyond repair (a subnegotiation with no end)."""


class ComPortCommand(enum.IntEnum):
    """RFC 2217 command codes, as the client sends them (the server adds 100)."""

    SIGNATURE = 0  #: text; empty asks the peer for its own
    SET_BAUDRATE = 1  #: 4 bytes, big-endian; 0 asks for the current rate
    SET_DATASIZE = 2  #: 5..8; 0 asks
    SET_PARITY = 3  #: 1 none, 2 odd, 3 even, 4 mark, 5 space; 0 asks
    SET_STOPSIZE = 4  #: 1 one, 2 two, 3 one and a half; 0 asks
    SET_CONTROL = 5  #: flow control, break, DTR, RTS
    NOTIFY_LINESTATE = 6  #: server to client: the line state changed
    NOTIFY_MODEMSTATE = 7  #: server to client: the modem lines changed
    FLOWCONTROL_SUSPEND = 8  #: the sender is to stop sending data
    FLOWCONTROL_RESUME = 9  #: it may send again
    SET_LINESTATE_MASK = 10  #: which line-state changes are notified
    SET_MODEMSTATE_MASK = 11  #: which modem-line changes are notified
    PURGE_DATA = 12  #: 1 the server's receive buffer, 2 its transmit buffer, 3 both


#: RFC 2217's parity values for LineSettings' letters.
PARITY_CODES: Final = {"N": 1, "O": 2, "E": 3}
#: PURGE-DATA's value that clears both of the server's buffers.
PURGE_BOTH: Final = 3


class LineState(enum.IntFlag):
    """NOTIFY-LINESTATE's bits (RFC 2217): the UART's receive and transmit state."""

    DATA_READY = 1
    OVERRUN_ERROR = 2
    PARITY_ERROR = 4
    FRAMING_ERROR = 8
    BREAK_DETECT = 16
    TRANSFER_HOLDING_EMPTY = 32
    TRANSFER_SHIFT_EMPTY = 64
    TIMEOUT_ERROR = 128


class ModemState(enum.IntFlag):
    """NOTIFY-MODEMSTATE's bits (RFC 2217): the modem lines and which of them changed."""

    DELTA_CTS = 1
    DELTA_DSR = 2
    TRAILING_EDGE_RI = 4
    DELTA_CD = 8
    CTS = 16
    DSR = 32
    RI = 64
    CD = 128


class Side(enum.Enum):
    """Whose option: the client's own (it says WILL, the server DO) or the server's."""

    LOCAL = "local"  #: we perform it: the server's DO / DONT ask, our WILL / WONT answer
    REMOTE = "remote"  #: the server performs it: its WILL / WONT, our DO / DONT


class OptState(enum.Enum):
    """One side of one option (RFC 1143)."""

    NO = "no"  #: disabled
    YES = "yes"  #: enabled
    WANT_NO = "want no"  #: we asked to disable it and wait for the answer
    WANT_YES = "want yes"  #: we asked to enable it and wait for the answer


# (state, the peer says yes, we accept the option) -> (next state, our answer):
# True says yes (WILL / DO), False says no (WONT / DONT), None says nothing.
# "Yes" received is WILL for the remote side and DO for the local side.
# An answer is sent only when the state changes on the peer's initiative:
# agreeing to what is already so, or answering an answer, would loop forever.
_TRANSITIONS: Final[dict[tuple[OptState, bool, bool], tuple[OptState, bool | None]]] = {
    (OptState.NO, True, True): (OptState.YES, True),  # the peer offers, we agree
    (OptState.NO, True, False): (OptState.NO, False),  # the peer offers, we refuse
    (OptState.NO, False, True): (OptState.NO, None),  # already off
    (OptState.NO, False, False): (OptState.NO, None),
    (OptState.YES, True, True): (OptState.YES, None),  # already on
    (OptState.YES, True, False): (OptState.YES, None),
    (OptState.YES, False, True): (OptState.NO, False),  # the peer turns it off: confirm
    (OptState.YES, False, False): (OptState.NO, False),
    (OptState.WANT_NO, True, True): (OptState.NO, None),  # RFC 1143: DONT answered by WILL
    (OptState.WANT_NO, True, False): (OptState.NO, None),
    (OptState.WANT_NO, False, True): (OptState.NO, None),  # our request granted
    (OptState.WANT_NO, False, False): (OptState.NO, None),
    (OptState.WANT_YES, True, True): (OptState.YES, None),  # our request granted
    (OptState.WANT_YES, True, False): (OptState.YES, None),
    (OptState.WANT_YES, False, True): (OptState.NO, None),  # our request refused
    (OptState.WANT_YES, False, False): (OptState.NO, None),
}

# A verb received: (its side, whether it says yes).
_RECEIVED: Final = {
    WILL: (Side.REMOTE, True),
    WONT: (Side.REMOTE, False),
    DO: (Side.LOCAL, True),
    DONT: (Side.LOCAL, False),
}
# Our answer on a side: (yes, no).
_ANSWER: Final = {Side.LOCAL: (WILL, WONT), Side.REMOTE: (DO, DONT)}


# -- events ----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Payload:
    """Serial bytes from the line, IAC-unescaped."""

    data: bytes


@dataclass(frozen=True, slots=True)
class OptionChanged:
    """An option was enabled or disabled on one side (also: a request of ours was refused)."""

    option: int
    side: Side
    enabled: bool


@dataclass(frozen=True, slots=True)
class ComPortReply:
    """The server's answer to a numeric COM-PORT command: the value now in force."""

    command: ComPortCommand
    value: int


@dataclass(frozen=True, slots=True)
class LineStateChanged:
    """NOTIFY-LINESTATE: the server's UART reported these line-state bits."""

    state: LineState


@dataclass(frozen=True, slots=True)
class ModemStateChanged:
    """NOTIFY-MODEMSTATE: the server's modem lines are now these."""

    state: ModemState


@dataclass(frozen=True, slots=True)
class FlowControl:
    """FLOWCONTROL-SUSPEND (``suspended``) or -RESUME from the server."""

    suspended: bool


@dataclass(frozen=True, slots=True)
class Signature:
    """The server's signature (its name and version, as it chose to give them)."""

    text: str


@dataclass(frozen=True, slots=True)
class SignatureRequested:
    """The server asked for the client's signature (the answer is in ``data_to_send()``)."""


@dataclass(frozen=True, slots=True)
class TelnetCommand:
    """A telnet command with no meaning on a serial line (NOP, GA, BRK, AYT...)."""

    code: int


@dataclass(frozen=True, slots=True)
class BadSubnegotiation:
    """A subnegotiation the client cannot use: another option's, malformed, or cut short."""

    option: int
    payload: bytes
    reason: str


TelnetEvent = (
    Payload
    | OptionChanged
    | ComPortReply
    | LineStateChanged
    | ModemStateChanged
    | FlowControl
    | Signature
    | SignatureRequested
    | TelnetCommand
    | BadSubnegotiation
)


# -- what the client sends -------------------------------------------------------------------


def escape(data: bytes) -> bytes:
    """Serial bytes as telnet data: every 0xFF doubled."""
    return data.replace(_IAC_BYTE, _IAC_IAC) if _IAC_BYTE in data else data


def com_port_command(command: ComPortCommand, value: int | bytes) -> bytes:
    """``IAC SB COM-PORT-OPTION <command> <value> IAC SE``, the value escaped.

    *value*: an int for the numeric commands (4 bytes for SET-BAUDRATE, 1 for
    the others), bytes for SIGNATURE, ``b""`` for FLOWCONTROL-SUSPEND/-RESUME.
    """
    if isinstance(value, bytes):
        raw = value
    elif command is ComPortCommand.SET_BAUDRATE:
        raw = value.to_bytes(4, "big")
    else:
        raw = value.to_bytes(1, "big")
    return bytes((IAC, SB, COM_PORT, command)) + escape(raw) + bytes((IAC, SE))


def line_commands(line: LineSettings) -> list[tuple[ComPortCommand, int]]:
    """The four SET commands that put the server's port to *line*, in RFC 2217's order."""
    return [
        (ComPortCommand.SET_BAUDRATE, line.baudrate),
        (ComPortCommand.SET_DATASIZE, line.bytesize),
        (ComPortCommand.SET_PARITY, PARITY_CODES[line.parity]),
        (ComPortCommand.SET_STOPSIZE, line.stopbits),
    ]


# -- the codec -------------------------------------------------------------------------------


class _Rx(enum.Enum):
    """Where the receiver is in the byte stream (see the module docstring's diagram)."""

    DATA = "data"
    IAC = "iac"
    VERB = "verb"
    SB = "sb"
    SB_DATA = "sb data"
    SB_IAC = "sb iac"


class TelnetCodec:
    """One telnet connection's receiver and option states, for the client's side.

    Args:
        local: the options the client agrees to perform (the server's DO is
            answered WILL; any other DO is answered WONT).
        remote: the options the client lets the server perform (its WILL is
            answered DO; any other WILL is answered DONT).
    """

    def __init__(self, local: frozenset[int], remote: frozenset[int]) -> None:
        self._accept = {Side.LOCAL: local, Side.REMOTE: remote}
        self._states: dict[tuple[Side, int], OptState] = {}
        self._rx = _Rx.DATA
        self._verb = 0
        self._sb_option = 0
        self._sb = bytearray()
        self._out = bytearray()

    def state(self, side: Side, option: int) -> OptState:
        """Where *option* stands on *side*."""
        return self._states.get((side, option), OptState.NO)

    def request(self, side: Side, option: int) -> bytes:
        """Ask to enable *option* on *side*: ``WILL`` (local) or ``DO`` (remote); b"" if it is on.

        The answer comes back as an :class:`OptionChanged` event from :meth:`feed`.
        """
        if self.state(side, option) is not OptState.NO:
            return b""
        self._states[side, option] = OptState.WANT_YES
        return bytes((IAC, _ANSWER[side][0], option))

    def data_to_send(self) -> bytes:
        """The bytes owed to the server since the last call (answers to its requests)."""
        out = bytes(self._out)
        self._out.clear()
        return out

    def feed(self, data: bytes) -> list[TelnetEvent]:
        """Decode *data* from the server into events, in the order they came.

        Raises:
            TelnetError: a subnegotiation longer than :data:`MAX_SUBNEGOTIATION`.
        """
        if self._rx is _Rx.DATA and _IAC_BYTE not in data:
            return [Payload(bytes(data))] if data else []  # the common case: plain serial bytes
        events: list[TelnetEvent] = []
        payload = bytearray()
        i, end = 0, len(data)
        while i < end:
            if self._rx is _Rx.DATA:
                j = data.find(_IAC_BYTE, i)
                if j < 0:
                    payload += data[i:]
                    break
                payload += data[i:j]
                i = j + 1
                self._rx = _Rx.IAC
                continue
            byte = data[i]
            i += 1
            if self._rx is _Rx.IAC and byte == IAC:
                payload.append(IAC)
                self._rx = _Rx.DATA
                continue
            if payload and self._rx is _Rx.IAC:
                # Whatever follows is not data: what came before it is delivered first.
                events.append(Payload(bytes(payload)))
                payload.clear()
            self._step(byte, events)
        if payload:
            events.append(Payload(bytes(payload)))
        return events

    def _step(self, byte: int, events: list[TelnetEvent]) -> None:
        """One byte in any state but DATA (and but IAC IAC, which :meth:`feed` keeps as data)."""
        rx = self._rx
        if rx is _Rx.IAC:
            if byte in _RECEIVED:
                self._verb = byte
                self._rx = _Rx.VERB
            elif byte == SB:
                self._rx = _Rx.SB
            else:
                events.append(TelnetCommand(byte))
                self._rx = _Rx.DATA
        elif rx is _Rx.VERB:
            self._negotiate(self._verb, byte, events)
            self._rx = _Rx.DATA
        elif rx is _Rx.SB:
            self._sb_option = byte
            self._sb.clear()
            self._rx = _Rx.SB_DATA
        elif rx is _Rx.SB_DATA:
            if byte == IAC:
                self._rx = _Rx.SB_IAC
            else:
                self._sb_byte(byte)
        else:  # SB_IAC
            if byte == IAC:
                self._sb_byte(IAC)
                self._rx = _Rx.SB_DATA
            elif byte == SE:
                self._rx = _Rx.DATA
                events.append(self._subnegotiation(self._sb_option, bytes(self._sb)))
            else:
                # RFC 854 has no IAC <x> inside a subnegotiation but IAC IAC and
                # IAC SE: the server cut it short. Report it, then read <x> as the
                # command it is.
                events.append(
                    BadSubnegotiation(self._sb_option, bytes(self._sb), f"cut short by IAC {byte}")
                )
                self._rx = _Rx.IAC
                self._step(byte, events)

    def _sb_byte(self, byte: int) -> None:
        if len(self._sb) >= MAX_SUBNEGOTIATION:
            raise TelnetError(
                f"subnegotiation of option {self._sb_option} longer than "
                f"{MAX_SUBNEGOTIATION} bytes with no IAC SE"
            )
        self._sb.append(byte)

    def _negotiate(self, verb: int, option: int, events: list[TelnetEvent]) -> None:
        side, says_yes = _RECEIVED[verb]
        before = self.state(side, option)
        after, answer = _TRANSITIONS[before, says_yes, option in self._accept[side]]
        self._states[side, option] = after
        if answer is not None:
            yes, no = _ANSWER[side]
            self._out += bytes((IAC, yes if answer else no, option))
        if after is not before:
            events.append(OptionChanged(option, side, after is OptState.YES))

    def _subnegotiation(self, option: int, payload: bytes) -> TelnetEvent:
        if option != COM_PORT:
            return BadSubnegotiation(option, payload, "not an option the client uses")
        if not payload or payload[0] < SERVER_OFFSET:
            return BadSubnegotiation(option, payload, "not a server's COM-PORT code")
        try:
            command = ComPortCommand(payload[0] - SERVER_OFFSET)
        except ValueError:
            return BadSubnegotiation(option, payload, f"unknown COM-PORT code {payload[0]}")
        value = payload[1:]
        if command is ComPortCommand.SIGNATURE:
            if not value:  # the server asks for ours
                self._out += com_port_command(ComPortCommand.SIGNATURE, CLIENT_SIGNATURE)
                return SignatureRequested()
            return Signature(value.decode("ascii", "replace"))
        if command in (ComPortCommand.FLOWCONTROL_SUSPEND, ComPortCommand.FLOWCONTROL_RESUME):
            return FlowControl(command is ComPortCommand.FLOWCONTROL_SUSPEND)
        size = 4 if command is ComPortCommand.SET_BAUDRATE else 1
        if len(value) != size:
            return BadSubnegotiation(
                option, payload, f"{command.name} with {len(value)} bytes of value, not {size}"
            )
        number = int.from_bytes(value, "big")
        if command is ComPortCommand.NOTIFY_LINESTATE:
            return LineStateChanged(LineState(number))
        if command is ComPortCommand.NOTIFY_MODEMSTATE:
            return ModemStateChanged(ModemState(number))
        return ComPortReply(command, number)
