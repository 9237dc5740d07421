"""The MQTT 3.1.1 codec: encoded bytes as the standard spells them, and the parser fed in chunks.

The expected bytes are written out from the standard's figures (section
numbers in each test), not from the encoder.
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sj300_async.gateway.mqttlink.client import MalformedPacket, PacketParser
from sj300_async.gateway.mqttlink.client._packets import (
    ConnAck,
    Oversized,
    PingResp,
    PubAck,
    Publish,
    SubAck,
    UnsubAck,
    encode_connect,
    encode_puback,
    encode_publish,
    encode_subscribe,
    encode_unsubscribe,
)


def test_connect_carries_the_will_and_the_credentials() -> None:
    # 3.1: protocol name "MQTT", level 4, flags, keepalive, then id, will, user, password.
    packet = encode_connect(
        "gw", keepalive_s=60, username="u", password="p", will=("t/a", b"off", 1, True)
    )
    body = (
        b"\x00\x04MQTT\x04"
        + bytes((0x80 | 0x40 | 0x20 | 0x08 | 0x04 | 0x02,))
        + b"\x00\x3c"
        + b"\x00\x02gw"
        + b"\x00\x03t/a\x00\x03off"
        + b"\x00\x01u\x00\x01p"
    )
    assert packet == b"\x10" + bytes((len(body),)) + body


def test_connect_without_will_or_credentials() -> None:
    assert encode_connect("c", keepalive_s=5, clean_session=False) == (
        b"\x10\x0d\x00\x04MQTT\x04\x00\x00\x05\x00\x01c"
    )


def test_publish_qos0_and_qos1() -> None:
    # 3.3: fixed header 0x30 | qos << 1 | retain; topic; packet id only at QoS > 0.
    assert encode_publish(b"a/b", b"hi") == b"\x30\x07\x00\x03a/bhi"
    assert encode_publish(b"a/b", b"hi", qos=1, retain=True, packet_id=258) == (
        b"\x33\x09\x00\x03a/b\x01\x02hi"
    )


def test_the_remaining_length_takes_more_bytes_as_it_grows() -> None:
    # 2.2.3: 128 is 0x80 0x01; 16,384 is 0x80 0x80 0x01.
    payload = b"x" * (128 - 5)
    assert encode_publish(b"a/b", payload)[:3] == b"\x30\x80\x01"
    payload = b"x" * (16_384 - 5)
    assert encode_publish(b"a/b", payload)[:4] == b"\x30\x80\x80\x01"


def test_subscribe_unsubscribe_puback() -> None:
    # 3.8.1: SUBSCRIBE's fixed header is 0x82; 3.10.1: UNSUBSCRIBE's 0xA2.
    assert encode_subscribe(10, [("a/#", 1), ("b", 0)]) == (
        b"\x82\x0c\x00\x0a\x00\x03a/#\x01\x00\x01b\x00"
    )
    assert encode_unsubscribe(11, ["a/#"]) == b"\xa2\x07\x00\x0b\x00\x03a/#"
    assert encode_puback(65535) == b"\x40\x02\xff\xff"


def test_what_a_broker_sends_is_parsed() -> None:
    stream = (
        b"\x20\x02\x01\x00"  # CONNACK, session present
        + b"\x90\x05\x00\x0a\x01\x00\x80"  # SUBACK: 1, 0, refused
        + b"\x40\x02\x01\x02"  # PUBACK 258
        + b"\xb0\x02\x00\x0b"  # UNSUBACK 11
        + b"\xd0\x00"  # PINGRESP
        + b"\x33\x09\x00\x03a/b\x00\x07hi"  # PUBLISH QoS 1, retained
    )
    assert PacketParser().feed(stream) == [
        ConnAck(True, 0),
        SubAck(10, (1, 0, 0x80)),
        PubAck(258),
        UnsubAck(11),
        PingResp(),
        Publish("a/b", b"hi", 1, True, 7),
    ]


@given(
    topic=st.text(min_size=1, max_size=40).filter(lambda t: "\x00" not in t),
    payloads=st.lists(st.binary(max_size=300), min_size=1, max_size=8),
    qos=st.sampled_from([0, 1]),
    cuts=st.lists(st.integers(min_value=1, max_value=64), max_size=40),
)
def test_any_chunking_gives_the_same_packets(
    topic: str, payloads: list[bytes], qos: int, cuts: list[int]
) -> None:
    stream = b"".join(
        encode_publish(topic.encode(), p, qos=qos, packet_id=i + 1 if qos else 0)
        for i, p in enumerate(payloads)
    )
    parser = PacketParser()
    got: list[object] = []
    at = 0
    for cut in cuts:
        got += parser.feed(stream[at : at + cut])
        at += cut
    got += parser.feed(stream[at:])
    assert got == [
        Publish(topic, p, qos, False, i + 1 if qos else None) for i, p in enumerate(payloads)
    ]


@pytest.mark.parametrize("step", [1, 3, 1000, 10_000])
def test_an_oversized_publish_is_skipped_and_the_next_one_read(step: int) -> None:
    big = encode_publish(b"big/t", b"x" * 5000, qos=1, packet_id=9)
    small = encode_publish(b"s", b"ok")
    stream = big + small
    parser = PacketParser(max_publish_bytes=1000)
    got: list[object] = []
    for at in range(0, len(stream), step):
        got += parser.feed(stream[at : at + step])
    assert got == [
        Oversized("big/t", 1, 9, False, 5000, b"x" * 256),
        Publish("s", b"ok", 0, False, None),
    ]
    assert not parser._buffer  # nothing of the big one was held


def test_the_limit_is_the_payload_s_a_long_topic_is_read() -> None:
    topic = "t" * 3000
    parser = PacketParser(max_publish_bytes=1000)
    assert parser.feed(encode_publish(topic.encode(), b"1")) == [
        Publish(topic, b"1", 0, False, None)
    ]
    assert parser.feed(encode_publish(topic.encode(), b"2" * 1001, retain=True)) == [
        Oversized(topic, 0, None, True, 1001, b"2" * 256)
    ]


@pytest.mark.parametrize(
    ("data", "says"),
    [
        (b"\x30\xff\xff\xff\xff\x01", "more than four bytes"),
        (b"\x35\x05\x00\x01a\x00\x01", "QoS 2"),
        (b"\x36\x05\x00\x01a\x00\x01", "QoS 3"),
        (b"\x32\x05\x00\x01a\x00\x00", "identifier 0"),
        (b"\x30\x03\x00\x05a", "shorter than its topic"),
        (b"\x30\x04\x00\x02\xff\xfe", "not UTF-8"),
        (b"\x20\x02\x02\x00", "CONNACK with flags"),
        (b"\x40\x03\x00\x01\x00", "PUBACK of 3 bytes"),
        (b"\x41\x02\x00\x01", "PUBACK with flags 0x1 and 2 bytes"),
        (b"\x40\xff\xff\xff\x7f", "PUBACK of 268435455 bytes"),  # judged before its body
        (b"\x90\x03\x00\x01\x03", "SUBACK with return codes 03"),
        (b"\xc0\x00", "PINGREQ from a broker"),
        (b"\x50\x02\x00\x01", "PUBREC from a broker"),
        (b"\xf0\x00", "packet type 15"),
    ],
)
def test_a_broken_packet_is_refused_with_what_broke(data: bytes, says: str) -> None:
    with pytest.raises(MalformedPacket, match=says):
        PacketParser().feed(data)


def test_encoders_refuse_what_mqtt_cannot_carry() -> None:
    with pytest.raises(ValueError, match="65535"):
        encode_subscribe(1, [("x" * 70_000, 0)])
    with pytest.raises(ValueError, match="keepalive"):
        encode_connect("c", keepalive_s=70_000)
