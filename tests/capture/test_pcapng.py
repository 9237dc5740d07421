"""The pcapng writer and reader: round trips, other writers' files, damaged files.

The reader is checked against files it did not write too: a big-endian
section built by hand from the specification's layout, and what Debian's
tshark reads back from ours (an independent pcapng implementation).
"""

from __future__ import annotations

import struct
import subprocess
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sj300_async.wire._pcapng import (
    FLAG_CHECK_ERROR,
    FLAG_NOISE,
    CapturedPacket,
    CaptureFormatError,
    PacketDirection,
    PcapngInterface,
    PcapngWriter,
    read_pcapng,
)

_SJ300 = PcapngInterface(147, name="tcp://bridge:4001", description="sj300 19200 8N1", speed=19200)


def _file(packets: list[CapturedPacket], *interfaces: PcapngInterface) -> bytes:
    writer = PcapngWriter()
    out = writer.section("test")
    for interface in interfaces or (_SJ300,):
        out += writer.interface(interface)[1]
    for packet in packets:
        out += writer.packet(packet)
    return out


packets_strategy = st.lists(
    st.builds(
        CapturedPacket,
        interface=st.just(0),
        timestamp_us=st.integers(0, 2**63 - 1),
        data=st.binary(max_size=600),
        direction=st.sampled_from(PacketDirection),
        flags=st.sampled_from([0, FLAG_CHECK_ERROR, FLAG_NOISE]),
        comment=st.text(max_size=40),
    ),
    max_size=20,
)


@given(packets_strategy)
def test_every_packet_reads_back_as_written(packets: list[CapturedPacket]) -> None:
    capture = read_pcapng(_file(packets))
    assert capture.interfaces == (_SJ300,)
    assert capture.application == "test"
    expected = [
        CapturedPacket(
            p.interface, p.timestamp_us, p.data, p.direction, p.flags | p.direction, p.comment
        )
        for p in packets
    ]
    assert list(capture.packets) == expected


def test_two_interfaces_keep_their_packets_apart() -> None:
    fr700 = PcapngInterface(148, name="serial:///dev/ttyUSB1", description="fr700 9600 8E2")
    packets = [
        CapturedPacket(0, 1_000_000, b"\x02010405\r", PacketDirection.OUTBOUND),
        CapturedPacket(1, 1_000_001, b"\x0501FD1C5", PacketDirection.OUTBOUND),
    ]
    capture = read_pcapng(_file(packets, _SJ300, fr700))
    assert [i.linktype for i in capture.interfaces] == [147, 148]
    assert [p.interface for p in capture.packets] == [0, 1]


def test_a_packet_of_an_interface_not_described_is_refused_when_written() -> None:
    writer = PcapngWriter()
    with pytest.raises(ValueError, match="no interface 0"):
        writer.packet(CapturedPacket(0, 0, b"x", PacketDirection.INBOUND))


def _be_block(block_type: int, body: bytes) -> bytes:
    body += b"\0" * (-len(body) % 4)
    length = 12 + len(body)
    return struct.pack(">II", block_type, length) + body + struct.pack(">I", length)


def test_a_big_endian_file_with_other_blocks_and_nanosecond_stamps_reads() -> None:
    """Built by hand from the layout in the pcapng specification, not by our writer."""
    shb = _be_block(0x0A0D0D0A, struct.pack(">IHHq", 0x1A2B3C4D, 1, 0, -1))
    tsresol = struct.pack(">HH", 9, 1) + b"\x09\0\0\0" + struct.pack(">HH", 0, 0)
    idb = _be_block(1, struct.pack(">HHI", 148, 0, 0) + tsresol)
    name_resolution = _be_block(4, b"\0\0\0\0")  # a block type the reader skips
    stamp_ns = 1_700_000_000_123_456_789
    data = b"\x0201E1107AD"
    flags = struct.pack(">HHI", 2, 4, 2) + struct.pack(">HH", 0, 0)
    epb_body = struct.pack(">IIIII", 0, stamp_ns >> 32, stamp_ns & 0xFFFFFFFF, len(data), len(data))
    epb = _be_block(6, epb_body + data + b"\0" * (-len(data) % 4) + flags)
    capture = read_pcapng(shb + idb + name_resolution + epb)
    assert capture.interfaces[0].linktype == 148
    (packet,) = capture.packets
    assert packet.data == data
    assert packet.timestamp_us == stamp_ns // 1000
    assert packet.direction is PacketDirection.OUTBOUND


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda b: b"", "not a pcapng file"),
        (lambda b: b"\0" * 40, "not a pcapng file"),
        (lambda b: b[:-3], "bad block length|ends inside"),
        (lambda b: b[:8] + b"\xff\xff\xff\xff" + b[12:], "byte-order magic"),
        (lambda b: b[:-4] + b"\0\0\0\0", "lengths differ"),
    ],
    ids=["empty", "zeros", "truncated", "magic", "trailer"],
)
def test_a_damaged_file_is_refused_with_where(damage: object, message: str) -> None:
    good = _file([CapturedPacket(0, 5, b"\x02010405\r", PacketDirection.OUTBOUND)])
    with pytest.raises(CaptureFormatError, match=message):
        read_pcapng(damage(good))  # type: ignore[operator]


@given(st.binary(max_size=300))
def test_garbage_never_raises_anything_but_a_format_error(noise: bytes) -> None:
    good = _file([CapturedPacket(0, 5, b"\x02010405\r", PacketDirection.OUTBOUND)])
    for data in (noise, good[:28] + noise, good + noise):
        try:
            read_pcapng(data)
        except CaptureFormatError:
            pass


def test_tshark_reads_our_file(tmp_path: Path) -> None:
    """tshark is one of the Debian packages `make test` installs: missing, this fails."""
    packets = [
        CapturedPacket(0, 1_700_000_000_000_000, b"\x02010405\r", PacketDirection.OUTBOUND),
        CapturedPacket(0, 1_700_000_000_011_000, b"\x0201xx\r", PacketDirection.INBOUND,
                       FLAG_CHECK_ERROR, "broken frame: bad BCC"),
    ]  # fmt: skip
    path = tmp_path / "x.pcapng"
    path.write_bytes(_file(packets))
    fields = (
        "frame.len",
        "frame.time_epoch",
        "frame.packet_flags_direction",
        "frame.packet_flags_crc_error",
        "frame.comment",
        "frame.interface_description",
    )
    result = subprocess.run(
        ["tshark", "-r", str(path), "-T", "fields", "-E", "separator=|"]
        + [arg for field in fields for arg in ("-e", field)],
        capture_output=True, text=True, timeout=60, check=True,
    )  # fmt: skip
    rows = [line.split("|") for line in result.stdout.splitlines()]
    assert [row[0] for row in rows] == ["8", "6"]
    assert [float(row[1]) for row in rows] == [1_700_000_000.0, 1_700_000_000.011]
    assert [int(row[2], 0) for row in rows] == [2, 1]  # outbound, inbound
    assert [row[3] for row in rows] == ["0", "1"]
    assert rows[1][4] == "broken frame: bad BCC"
    assert rows[0][5] == "sj300 19200 8N1"
