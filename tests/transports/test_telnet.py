"""The sans-IO telnet / RFC 2217 codec (sj300_async.transports._telnet), without a socket.

- serial bytes survive escape -> feed whatever the chunking, 0xFF included;
- a stream of data, negotiation, subnegotiations and commands, built by a
  reference encoder written here from RFC 854 / 2217, decodes to the same
  events however it is cut (hypothesis), and so does a cut inside IAC IAC or
  inside a subnegotiation at every position;
- options the client does not use are refused (DONT / WONT), the ones it
  does are agreed once (no answer to an answer), refusals of its own
  requests are reported;
- malformed, foreign or overlong subnegotiations are reported or refused,
  never taken as data;
- the module imports nothing that does I/O.
"""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from sans_io_scan import WIRE, module_violations

from sj300_async import LineSettings
from sj300_async.transports._telnet import (
    MAX_SUBNEGOTIATION,
    BadSubnegotiation,
    ComPortCommand,
    ComPortReply,
    FlowControl,
    LineState,
    LineStateChanged,
    ModemState,
    ModemStateChanged,
    OptionChanged,
    OptState,
    Payload,
    Side,
    Signature,
    SignatureRequested,
    TelnetCodec,
    TelnetCommand,
    TelnetError,
    TelnetEvent,
    com_port_command,
    escape,
    line_commands,
)

PROPERTY = settings(max_examples=300, deadline=None)

# RFC 854 / 2217 numbers, written out again here so the tests do not take the codec's word.
IAC, DONT, DO, WONT, WILL, SB, SE, NOP, GA = 255, 254, 253, 252, 251, 250, 240, 241, 249
BINARY, ECHO, SGA, TTYPE, COM_PORT = 0, 1, 3, 24, 44


def codec() -> TelnetCodec:
    """The client's codec as the RFC 2217 transport makes it."""
    return TelnetCodec(local=frozenset({BINARY, SGA, COM_PORT}), remote=frozenset({BINARY, SGA}))


def ref_sb(option: int, payload: bytes) -> bytes:
    """Reference encoder: a subnegotiation, IAC doubled inside."""
    return bytes([IAC, SB, option]) + payload.replace(b"\xff", b"\xff\xff") + bytes([IAC, SE])


def ref_reply(command: int, value: bytes) -> bytes:
    """Reference encoder: the server's COM-PORT answer to *command* (its code plus 100)."""
    return ref_sb(COM_PORT, bytes([100 + command]) + value)


def merged(events: list[TelnetEvent]) -> list[TelnetEvent]:
    """Adjacent Payload events joined: how serial bytes are cut into events is not a result."""
    out: list[TelnetEvent] = []
    for event in events:
        if isinstance(event, Payload) and out and isinstance(out[-1], Payload):
            out[-1] = Payload(out[-1].data + event.data)
        else:
            out.append(event)
    return out


def feed_in_chunks(c: TelnetCodec, stream: bytes, cuts: list[int]) -> list[TelnetEvent]:
    events: list[TelnetEvent] = []
    bounds = [0, *sorted({min(cut, len(stream)) for cut in cuts}), len(stream)]
    for start, end in itertools.pairwise(bounds):
        events += c.feed(stream[start:end])
    return events


# -- data --------------------------------------------------------------------------------------


def test_plain_data_is_passed_as_it_came() -> None:
    assert codec().feed(b"\x0201040\x05\r") == [Payload(b"\x0201040\x05\r")]
    assert codec().feed(b"") == []


def test_ff_is_doubled_on_the_way_out_and_single_on_the_way_in() -> None:
    assert escape(b"a\xffb\xff\xff") == b"a\xff\xffb\xff\xff\xff\xff"
    assert escape(b"abc") == b"abc"
    assert codec().feed(b"a\xff\xffb") == [Payload(b"a\xffb")]


def test_iac_iac_split_between_chunks() -> None:
    c = codec()
    assert c.feed(b"a\xff") == [Payload(b"a")]
    assert c.feed(b"\xffb") == [Payload(b"\xffb")]
    assert c.feed(b"\xff") == []
    assert c.feed(b"\xff") == [Payload(b"\xff")]


@PROPERTY
@given(st.binary(max_size=300), st.lists(st.integers(0, 700), max_size=12))
def test_escaped_data_round_trips_however_it_is_cut(data: bytes, cuts: list[int]) -> None:
    c = codec()
    events = feed_in_chunks(c, escape(data), cuts)
    assert all(isinstance(e, Payload) for e in events)
    assert b"".join(e.data for e in events if isinstance(e, Payload)) == data
    assert c.data_to_send() == b""


def test_other_telnet_commands_are_reported_in_order_between_the_data() -> None:
    events = codec().feed(b"ab" + bytes([IAC, NOP]) + b"cd" + bytes([IAC, GA]))
    assert events == [Payload(b"ab"), TelnetCommand(NOP), Payload(b"cd"), TelnetCommand(GA)]


# -- option negotiation ------------------------------------------------------------------------


def test_options_the_client_does_not_use_are_refused() -> None:
    c = codec()
    # ser2net offers to echo; a terminal-type request would come as DO TTYPE.
    assert c.feed(bytes([IAC, WILL, ECHO, IAC, DO, TTYPE])) == []
    assert c.data_to_send() == bytes([IAC, DONT, ECHO, IAC, WONT, TTYPE])
    assert c.state(Side.REMOTE, ECHO) is OptState.NO
    assert c.state(Side.LOCAL, TTYPE) is OptState.NO
    # Asked again, refused again (the state did not move, so this is no loop).
    c.feed(bytes([IAC, DO, TTYPE]))
    assert c.data_to_send() == bytes([IAC, WONT, TTYPE])


def test_a_refused_option_being_turned_off_needs_no_answer() -> None:
    c = codec()
    c.feed(bytes([IAC, WONT, ECHO, IAC, DONT, TTYPE]))
    assert c.data_to_send() == b""


def test_offers_the_client_accepts_are_agreed_once() -> None:
    c = codec()
    events = c.feed(bytes([IAC, DO, BINARY, IAC, WILL, BINARY]))
    assert events == [
        OptionChanged(BINARY, Side.LOCAL, True),
        OptionChanged(BINARY, Side.REMOTE, True),
    ]
    assert c.data_to_send() == bytes([IAC, WILL, BINARY, IAC, DO, BINARY])
    # The same offer again is already in force: answering it would loop forever.
    assert c.feed(bytes([IAC, DO, BINARY, IAC, WILL, BINARY])) == []
    assert c.data_to_send() == b""


def test_a_request_answered_yes_is_not_answered_again() -> None:
    c = codec()
    assert c.request(Side.LOCAL, COM_PORT) == bytes([IAC, WILL, COM_PORT])
    assert c.state(Side.LOCAL, COM_PORT) is OptState.WANT_YES
    assert c.request(Side.LOCAL, COM_PORT) == b""  # already asked
    assert c.feed(bytes([IAC, DO, COM_PORT])) == [OptionChanged(COM_PORT, Side.LOCAL, True)]
    assert c.data_to_send() == b""
    assert c.state(Side.LOCAL, COM_PORT) is OptState.YES


def test_a_request_refused_is_reported() -> None:
    c = codec()
    c.request(Side.LOCAL, COM_PORT)
    assert c.feed(bytes([IAC, DONT, COM_PORT])) == [OptionChanged(COM_PORT, Side.LOCAL, False)]
    assert c.data_to_send() == b""
    assert c.state(Side.LOCAL, COM_PORT) is OptState.NO


def test_an_agreed_option_turned_off_by_the_server_is_confirmed() -> None:
    c = codec()
    c.feed(bytes([IAC, WILL, SGA]))
    c.data_to_send()
    assert c.feed(bytes([IAC, WONT, SGA])) == [OptionChanged(SGA, Side.REMOTE, False)]
    assert c.data_to_send() == bytes([IAC, DONT, SGA])


def test_ser2net_greeting() -> None:
    """What ser2net 4.3 sends on connection (captured), answered as RFC 1143 says."""
    c = codec()
    for side, option in ((Side.LOCAL, BINARY), (Side.REMOTE, BINARY), (Side.LOCAL, COM_PORT)):
        c.request(side, option)
    greeting = bytes.fromhex("fffb03 fffd03 fffb01 fffe01 fffd00 fffb00 fffd2c")
    events = c.feed(greeting)
    assert OptionChanged(COM_PORT, Side.LOCAL, True) in events
    assert c.state(Side.LOCAL, BINARY) is c.state(Side.REMOTE, BINARY) is OptState.YES
    # SGA offered both ways is agreed; ECHO is refused; what the client asked is not re-answered.
    assert c.data_to_send() == bytes([IAC, DO, SGA, IAC, WILL, SGA, IAC, DONT, ECHO])


# -- RFC 2217 subnegotiations ------------------------------------------------------------------


def test_the_clients_commands_are_encoded_as_rfc_2217_says() -> None:
    assert com_port_command(ComPortCommand.SET_BAUDRATE, 19200) == bytes.fromhex(
        "fffa2c01 00004b00 fff0"
    )
    assert com_port_command(ComPortCommand.PURGE_DATA, 3) == bytes.fromhex("fffa2c0c03fff0")
    # 255 baud: the value's 0xFF is doubled inside the subnegotiation too.
    assert com_port_command(ComPortCommand.SET_BAUDRATE, 255) == bytes.fromhex(
        "fffa2c01 000000ffff fff0"
    )
    assert com_port_command(ComPortCommand.SIGNATURE, b"x") == bytes.fromhex("fffa2c0078fff0")
    assert line_commands(LineSettings(9600, 7, "E", 2)) == [
        (ComPortCommand.SET_BAUDRATE, 9600),
        (ComPortCommand.SET_DATASIZE, 7),
        (ComPortCommand.SET_PARITY, 3),
        (ComPortCommand.SET_STOPSIZE, 2),
    ]
    assert line_commands(LineSettings(19200, 8, "O", 1))[2] == (ComPortCommand.SET_PARITY, 2)


def test_the_servers_answers_and_notifications() -> None:
    stream = (
        ref_reply(1, (19200).to_bytes(4, "big"))
        + ref_reply(2, b"\x08")
        + ref_reply(3, b"\x01")
        + ref_reply(4, b"\x01")
        + ref_reply(12, b"\x03")
        + ref_reply(6, b"\x0a")
        + ref_reply(7, b"\x30")
        + ref_reply(8, b"")
        + ref_reply(9, b"")
        + ref_reply(0, b"ser2net 4.3")
    )
    assert codec().feed(stream) == [
        ComPortReply(ComPortCommand.SET_BAUDRATE, 19200),
        ComPortReply(ComPortCommand.SET_DATASIZE, 8),
        ComPortReply(ComPortCommand.SET_PARITY, 1),
        ComPortReply(ComPortCommand.SET_STOPSIZE, 1),
        ComPortReply(ComPortCommand.PURGE_DATA, 3),
        LineStateChanged(LineState.OVERRUN_ERROR | LineState.FRAMING_ERROR),
        ModemStateChanged(ModemState.CTS | ModemState.DSR),
        FlowControl(suspended=True),
        FlowControl(suspended=False),
        Signature("ser2net 4.3"),
    ]


def test_a_baud_rate_with_ff_in_it_is_read_back() -> None:
    assert codec().feed(ref_reply(1, (0x1FF).to_bytes(4, "big"))) == [
        ComPortReply(ComPortCommand.SET_BAUDRATE, 0x1FF)
    ]


def test_a_subnegotiation_cut_at_every_position() -> None:
    stream = b"ab" + ref_reply(1, (0xFF00FF).to_bytes(4, "big")) + b"c\xff\xffd"
    whole = codec().feed(stream)
    assert merged(whole) == [
        Payload(b"ab"),
        ComPortReply(ComPortCommand.SET_BAUDRATE, 0xFF00FF),
        Payload(b"c\xffd"),
    ]
    for cut in range(1, len(stream)):
        c = codec()
        assert merged(c.feed(stream[:cut]) + c.feed(stream[cut:])) == whole, cut


def test_the_server_asking_for_the_clients_signature_is_answered() -> None:
    c = codec()
    assert c.feed(ref_reply(0, b"")) == [SignatureRequested()]
    assert c.data_to_send() == bytes([IAC, SB, COM_PORT, 0]) + b"sj300_async" + bytes([IAC, SE])


@pytest.mark.parametrize(
    ("stream", "reason"),
    [
        pytest.param(ref_sb(TTYPE, b"\x01"), "not an option the client uses", id="other-option"),
        pytest.param(
            ref_sb(COM_PORT, b"\x01\x00"), "not a server's COM-PORT code", id="client-code"
        ),
        pytest.param(ref_sb(COM_PORT, b""), "not a server's COM-PORT code", id="empty"),
        pytest.param(ref_reply(50, b"\x01"), "unknown COM-PORT code 150", id="unknown-code"),
        pytest.param(
            ref_reply(1, b"\x00\x4b\x00"), "SET_BAUDRATE with 3 bytes of value, not 4", id="short"
        ),
        pytest.param(
            ref_reply(7, b"\x01\x02"), "NOTIFY_MODEMSTATE with 2 bytes of value, not 1", id="long"
        ),
    ],
)
def test_subnegotiations_the_client_cannot_use_are_reported(stream: bytes, reason: str) -> None:
    (event,) = codec().feed(b"x" + stream + b"y")[1:-1]
    assert isinstance(event, BadSubnegotiation)
    assert event.reason == reason


def test_a_subnegotiation_cut_short_is_reported_and_the_command_read() -> None:
    c = codec()
    events = c.feed(bytes([IAC, SB, COM_PORT, 107, IAC, WILL, ECHO]) + b"z")
    assert events == [
        BadSubnegotiation(COM_PORT, bytes([107]), f"cut short by IAC {WILL}"),
        Payload(b"z"),
    ]
    assert c.data_to_send() == bytes([IAC, DONT, ECHO])


def test_a_subnegotiation_without_end_is_an_error_not_a_growing_buffer() -> None:
    c = codec()
    c.feed(bytes([IAC, SB, COM_PORT]) + b"\x00" * MAX_SUBNEGOTIATION)
    with pytest.raises(TelnetError, match="longer than 1024 bytes"):
        c.feed(b"\x00")


# -- the whole stream, cut anywhere (hypothesis) -----------------------------------------------

_ITEMS = st.one_of(
    st.binary(min_size=1, max_size=40).map(lambda d: ("data", d)),
    st.sampled_from([WILL, WONT, DO, DONT]).flatmap(
        lambda verb: st.sampled_from([BINARY, ECHO, SGA, TTYPE, COM_PORT]).map(
            lambda option: ("verb", bytes([verb, option]))
        )
    ),
    st.integers(0, 2**32 - 1).map(lambda baud: ("baud", baud)),
    st.integers(0, 255).map(lambda bits: ("modem", bits)),
    st.sampled_from([NOP, GA]).map(lambda code: ("command", code)),
)


def _encode(item: tuple[str, object]) -> bytes:
    kind, value = item
    if kind == "data":
        assert isinstance(value, bytes)
        return value.replace(b"\xff", b"\xff\xff")
    if kind == "verb":
        assert isinstance(value, bytes)
        return bytes([IAC]) + value
    if kind == "baud":
        assert isinstance(value, int)
        return ref_reply(1, value.to_bytes(4, "big"))
    if kind == "modem":
        assert isinstance(value, int)
        return ref_reply(7, bytes([value]))
    assert isinstance(value, int)
    return bytes([IAC, value])


@PROPERTY
@given(st.lists(_ITEMS, max_size=25), st.lists(st.integers(0, 1500), max_size=20))
def test_events_and_answers_do_not_depend_on_how_the_stream_is_cut(
    items: list[tuple[str, object]], cuts: list[int]
) -> None:
    stream = b"".join(_encode(item) for item in items)
    whole = codec()
    expected = merged(whole.feed(stream))
    chunked = codec()
    assert merged(feed_in_chunks(chunked, stream, cuts)) == expected
    assert chunked.data_to_send() == whole.data_to_send()
    # And the serial bytes are exactly the data items, in order.
    data = b"".join(v for k, v in items if k == "data" and isinstance(v, bytes))
    assert b"".join(e.data for e in expected if isinstance(e, Payload)) == data
    bauds = [v for k, v in items if k == "baud"]
    assert [e.value for e in expected if isinstance(e, ComPortReply)] == bauds


@PROPERTY
@given(st.binary(max_size=200))
def test_garbage_never_raises_but_for_an_overlong_subnegotiation(stream: bytes) -> None:
    events = codec().feed(stream)  # under the cap, so no TelnetError
    payload = b"".join(e.data for e in events if isinstance(e, Payload))
    assert all(not isinstance(e, Payload) or e.data for e in events)  # no empty events
    assert len(payload) <= len(stream)


# -- sans-IO -----------------------------------------------------------------------------------


def test_the_codec_imports_no_io() -> None:
    assert module_violations("transports._telnet", allowed=WIRE) == []
