"""The Wireshark dissector (contrib/wireshark/sj300_async.lua), read by Debian's tshark.

Each test makes a capture with the library (the simulator's buses, or the
pcapng writer for a tap whose direction is unknown), runs ``tshark -2`` with
the dissector, and compares the decoded fields packet by packet: node or
station, command or instruction, reply kind or format, NAK code, check code,
and the request/reply pairing (``-2``: the first pass pairs, the second
shows it both ways).

tshark runs with an empty HOME, so no personal preference or plugin takes
part (an installed copy of the dissector would register its protocols a
second time). It runs as root here and says so on stderr; that warning is
expected. A Lua error shows either on stderr (``tshark: Lua: ...`` while
loading) or as an expert message ``Lua Error: ...`` on the packet: both
fail the test.
"""

from __future__ import annotations

import random
from pathlib import Path

import pytest
from tshark import FR700_FIELDS, SJ300_FIELDS, Row, decode, table

import sj300_async
from sj300_async import Direction, NakError
from sj300_async.bus import CaptureFile
from sj300_async.fr700 import (
    Fr700LineOptions,
    encode_ack,
    encode_data_reply,
    encode_host_ack,
    encode_nak,
    encode_reoutput_request,
)
from sj300_async.fr700 import encode_request as fr700_request
from sj300_async.sj300 import AckDataReply, AckReply, DataReply, NakCode, NakReply, encode_reply
from sj300_async.sj300 import encode_request as sj300_request
from sj300_async.wire._pcapng import (
    FLAG_NOISE,
    CapturedPacket,
    PacketDirection,
    PcapngInterface,
    PcapngWriter,
    read_pcapng,
)

#: A fixed response time-out far above any reply's (about 10 ms at 19200 baud): a busy
#: machine must not turn an exchange into a time-out and a retry, which would add packets
#: to the capture. Not more: after the damaged reply the bus waits out a time-out.
SLACK_S = 1.0


def check_response_times(rows: list[Row], capture: Path, prefix: str) -> int:
    """Each reply's response time is its request's to its own timestamp, to the µs."""
    stamps = [packet.timestamp_us for packet in read_pcapng(capture.read_bytes()).packets]
    checked = 0
    for number, row in enumerate(rows, 1):
        if row[f"{prefix}.type"] != "reply" or not row[f"{prefix}.request_in"]:
            continue
        request = int(row[f"{prefix}.request_in"])
        seconds = float(row[f"{prefix}.response_time"])
        assert round(seconds * 1e6) == stamps[number - 1] - stamps[request - 1], row
        checked += 1
    return checked


async def test_sj300_exchange(tmp_path: Path) -> None:
    capture = tmp_path / "sj300.pcapng"
    async with sj300_async.open_bus(
        "sim://?nodes=1-3&baudrate=19200", capture=capture, timeout=SLACK_S
    ) as bus:
        assert bus.simulator is not None
        await bus.drive(1).read_status()
        with pytest.raises(NakError):
            await bus.drive(1).read_parameter_raw("A999")  # no such parameter: NAK 16
        bus.simulator.faults.corrupt_next(2)
        await bus.drive(2).read_status()  # a damaged reply, then a sync request and a retry
        await bus.broadcast.set_frequency(10.0)
        await bus.drive(3).read_parameter_raw("A004")

    fields = (*SJ300_FIELDS, "sj300.broadcast", "sj300.param", "sj300.response_time")
    rows = decode(capture, fields, tmp_path / "home")
    assert table(rows, SJ300_FIELDS) == [
        ("request", "1", "0x04", "", "", "1", "", "2"),
        ("reply", "1", "0x04", "data", "", "1", "1", ""),
        ("request", "1", "0x06", "", "", "1", "", "4"),
        ("reply", "1", "0x06", "NAK", "16", "1", "3", ""),
        ("request", "2", "0x04", "", "", "1", "", "6"),
        ("reply", "2", "0x04", "data", "", "0", "5", ""),
        ("request", "2", "0x09", "", "", "1", "", "8"),
        ("reply", "2", "0x09", "ACK+data", "", "1", "7", ""),
        ("request", "2", "0x04", "", "", "1", "", "10"),
        ("reply", "2", "0x04", "data", "", "1", "9", ""),
        ("request", "255", "0x01", "", "", "1", "", ""),
        ("request", "3", "0x06", "", "", "1", "", "13"),
        ("reply", "3", "0x06", "ACK+data", "", "1", "12", ""),
    ]
    assert [row["sj300.broadcast"] for row in rows] == [""] * 10 + ["1", "", ""]
    assert rows[2]["sj300.param"] == "A999"
    assert "NAK 16: abnormal parameter code or value" in rows[3]["_ws.expert.message"]
    assert "Wrong BCC" in rows[5]["_ws.expert.message"]
    assert check_response_times(rows, capture, "sj300") == 6


async def test_fr700_exchange(tmp_path: Path) -> None:
    capture = tmp_path / "fr700.pcapng"
    with CaptureFile(capture) as lines:
        # The host acknowledges read data (ack=1); requests carry the waiting time; CR.
        url = "sim://?nodes=1-3&ack=1"
        async with sj300_async.open_bus(
            url, protocol="fr700", capture=lines, timeout=SLACK_S
        ) as bus:
            assert bus.simulator is not None
            await bus.drive(1).read_status()
            with pytest.raises(NakError):
                await bus.drive(1).read(0x78)  # no such instruction: NAK B
            bus.simulator.faults.corrupt_next(2)
            await bus.drive(2).read_status()  # damaged data: the host asks for it again
            await bus.drive(3).set_frequency(50.0)
            await bus.drive(1).multi_command(Direction.FORWARD, 10.0)
        # Another line: no waiting-time character, CR LF, no host ACK.
        url = "sim://?nodes=1-3&wait_field=0&terminator=crlf"
        async with sj300_async.open_bus(
            url, protocol="fr700", capture=lines, timeout=SLACK_S
        ) as bus:
            await bus.drive(2).read_output_frequency()
            await bus.drive(2).run_forward()

    fields = (*FR700_FIELDS, "fr700.answer_in", "fr700.response_time", "frame.interface_id")
    rows = decode(capture, fields, tmp_path / "home")
    assert table(rows, FR700_FIELDS) == [
        ("request", "B", "1", "0x7a", "0", "", "1", "", "2", "", "CR"),
        ("reply", "E1", "1", "0x7a", "", "", "1", "1", "", "", "CR"),
        ("host_answer", "C", "1", "0x7a", "", "", "", "1", "", "2", "CR"),
        ("request", "B", "1", "0x78", "0", "", "1", "", "5", "", "CR"),
        ("reply", "D", "1", "0x78", "", "0x0b", "", "4", "", "", "CR"),
        ("request", "B", "2", "0x7a", "0", "", "1", "", "7;9", "", "CR"),
        ("reply", "E1", "2", "0x7a", "", "", "0", "6", "", "", "CR"),
        ("host_answer", "F", "2", "0x7a", "", "", "", "6", "", "7", "CR"),
        ("reply", "E1", "2", "0x7a", "", "", "1", "6", "", "", "CR"),
        ("host_answer", "C", "2", "0x7a", "", "", "", "6", "", "9", "CR"),
        ("request", "A", "3", "0xed", "0", "", "1", "", "12", "", "CR"),
        ("reply", "C", "3", "0xed", "", "", "", "11", "", "", "CR"),
        ("request", "A2", "1", "0xf0", "0", "", "1", "", "14", "", "CR"),
        ("reply", "C1", "1", "0xf0", "", "", "1", "13", "", "", "CR"),
        ("host_answer", "C", "1", "0xf0", "", "", "", "13", "", "14", "CR"),
        ("request", "B", "2", "0x6f", "", "", "1", "", "17", "", "CR LF"),
        ("reply", "E", "2", "0x6f", "", "", "1", "16", "", "", "CR LF"),
        ("request", "A1", "2", "0xfa", "", "", "1", "", "19", "", "CR LF"),
        ("reply", "C", "2", "0xfa", "", "", "", "18", "", "", "CR LF"),
    ]
    assert [row["fr700.answer_in"] for row in rows if row["fr700.answer_in"]] == [
        "3",
        "8",
        "10",
        "15",
    ]
    assert [row["frame.interface_id"] for row in rows] == ["0"] * 15 + ["1"] * 4
    assert "NAK B: instruction code error" in rows[4]["_ws.expert.message"]
    assert "Wrong sum check" in rows[6]["_ws.expert.message"]
    assert check_response_times(rows, capture, "fr700") == 8


def _tap_capture(path: Path, linktype: int, packets: list[tuple[bytes, PacketDirection]]) -> None:
    """A capture as a tap writes it: the direction unknown unless given, noise marked."""
    writer = PcapngWriter()
    data = writer.section("test") + writer.interface(PcapngInterface(linktype, "tap"))[1]
    for n, (frame, direction) in enumerate(packets):
        flags = FLAG_NOISE if frame.startswith(b"\0") else 0
        data += writer.packet(
            CapturedPacket(0, 1_700_000_000_000_000 + 10_000 * n, frame, direction, flags)
        )
    path.write_bytes(data)


def test_sj300_direction_from_content(tmp_path: Path) -> None:
    unknown, outbound, inbound = (
        PacketDirection.UNKNOWN,
        PacketDirection.OUTBOUND,
        PacketDirection.INBOUND,
    )
    read_a004 = sj300_request(2, 0x06, b"A004")
    bad_bcc = encode_reply(DataReply(1, b"02000100"))[:-3] + b"00\r"
    _tap_capture(tmp_path / "tap.pcapng", 147, [
        (sj300_request(1, 0x04), unknown),
        # As long as a set-frequency request: a reply, since a status read of node 1 is pending.
        (encode_reply(DataReply(1, b"02000100")), unknown),
        (sj300_request(1, 0x01, b"005000"), unknown),  # nothing pending: a request
        (encode_reply(AckReply(1)), unknown),
        (b"\0\xffnoise", unknown),
        (read_a004, outbound),
        (read_a004, inbound),  # the adapter's local echo
        (encode_reply(AckDataReply(2, b"00000300")), inbound),
        (sj300_request(3, 0x04), unknown),
        (encode_reply(NakReply(3, NakCode.CHECKSUM)), unknown),
        (sj300_request(1, 0x04), unknown),
        (bad_bcc, unknown),
    ])  # fmt: skip
    rows = decode(tmp_path / "tap.pcapng", (*SJ300_FIELDS, "sj300.frequency"), tmp_path / "home")
    assert table(rows, SJ300_FIELDS) == [
        ("request", "1", "0x04", "", "", "1", "", "2"),
        ("reply", "1", "0x04", "data", "", "1", "1", ""),
        ("request", "1", "0x01", "", "", "1", "", "4"),
        ("reply", "1", "0x01", "ACK", "", "1", "3", ""),
        ("noise", "", "", "", "", "", "", ""),
        ("request", "2", "0x06", "", "", "1", "", "8"),
        ("echo", "2", "0x06", "", "", "1", "", ""),
        ("reply", "2", "0x06", "ACK+data", "", "1", "6", ""),
        ("request", "3", "0x04", "", "", "1", "", "10"),
        ("reply", "3", "0x04", "NAK", "2", "1", "9", ""),
        ("request", "1", "0x04", "", "", "1", "", "12"),
        ("reply", "1", "0x04", "data", "", "0", "11", ""),
    ]
    assert rows[2]["sj300.frequency"] == "50"
    assert "Noise" in rows[4]["_ws.expert.message"]


def test_fr700_direction_from_content(tmp_path: Path) -> None:
    unknown = PacketDirection.UNKNOWN
    options = Fr700LineOptions(wait_time_digit=3)
    _tap_capture(tmp_path / "tap.pcapng", 148, [
        (fr700_request(1, 0x7A, options=options), unknown),
        (encode_data_reply(1, b"02"), unknown),
        (encode_host_ack(1), unknown),  # ACK after read data: the host's
        (fr700_request(1, 0xFA, b"02", options=options), unknown),
        (encode_ack(1), unknown),  # ACK to a write: the drive's
        (fr700_request(4, 0x6F, options=options), unknown),
        (encode_data_reply(4, b"1770")[:-3] + b"00\r", unknown),
        (encode_reoutput_request(4), unknown),  # NAK without a code: the host's
        (encode_data_reply(4, b"1770"), unknown),
        (fr700_request(5, 0xFB, b"0000", options=options), unknown),
        (encode_nak(5, 0xA), unknown),  # NAK with a code: the drive's
        (b"\0\xffnoise", unknown),
    ])  # fmt: skip
    rows = decode(tmp_path / "tap.pcapng", (*FR700_FIELDS, "fr700.frequency"), tmp_path / "home")
    assert table(rows, FR700_FIELDS) == [
        ("request", "B", "1", "0x7a", "3", "", "1", "", "2", "", "CR"),
        ("reply", "E1", "1", "0x7a", "", "", "1", "1", "", "", "CR"),
        ("host_answer", "C", "1", "0x7a", "", "", "", "1", "", "2", "CR"),
        ("request", "A1", "1", "0xfa", "3", "", "1", "", "5", "", "CR"),
        ("reply", "C", "1", "0xfa", "", "", "", "4", "", "", "CR"),
        ("request", "B", "4", "0x6f", "3", "", "1", "", "7;9", "", "CR"),
        ("reply", "E", "4", "0x6f", "", "", "0", "6", "", "", "CR"),
        ("host_answer", "F", "4", "0x6f", "", "", "", "6", "", "7", "CR"),
        ("reply", "E", "4", "0x6f", "", "", "1", "6", "", "", "CR"),
        ("request", "A", "5", "0xfb", "3", "", "1", "", "11", "", "CR"),
        ("reply", "D", "5", "0xfb", "", "0x0a", "", "10", "", "", "CR"),
        ("noise", "", "", "", "", "", "", "", "", "", ""),
    ]
    assert rows[8]["fr700.frequency"] == "60"


_MARKS = b"\x02\x03\x05\x06\x0a\x0d\x150123456789ABCDEFaf"


def _damage(frame: bytes, rng: random.Random) -> bytes:
    """One to three edits: a byte replaced, dropped or inserted, or the frame cut."""
    data = bytearray(frame)
    for _ in range(rng.randint(1, 3)):
        at = rng.randrange(len(data) + 1)
        edit = rng.randrange(4)
        byte = rng.choice(_MARKS) if rng.random() < 0.8 else rng.randrange(256)
        if edit == 0 and at < len(data):
            data[at] = byte
        elif edit == 1 and at < len(data) and len(data) > 1:
            del data[at]
        elif edit == 2:
            data.insert(at, byte)
        elif at:
            del data[at:]
    return bytes(data)


@pytest.mark.parametrize("linktype", [147, 148])
def test_damaged_frames_decode_without_lua_errors(tmp_path: Path, linktype: int) -> None:
    """Frames edited at random, in every direction: each packet decodes, no Lua error."""
    if linktype == 147:
        good = [
            sj300_request(1, 0x04),
            sj300_request(0xFF, 0x01, b"005000"),
            sj300_request(2, 0x07, b"A00400000500"),
            encode_reply(DataReply(1, b"02000100")),
            encode_reply(AckDataReply(2, b"00000300")),
            encode_reply(NakReply(3, NakCode.ABNORMAL_PARAMETER)),
            encode_reply(AckReply(4)),
        ]
    else:
        options = Fr700LineOptions(wait_field=False, terminator=b"\r\n")
        good = [
            fr700_request(1, 0x7A),
            fr700_request(2, 0xED, b"1770", options=options),
            fr700_request(3, 0xF0, b"0000020000"),
            encode_data_reply(1, b"02"),
            encode_data_reply(3, b"00FF17700000"),
            encode_ack(2),
            encode_nak(3, 0xB),
            encode_reoutput_request(1),
        ]
    rng = random.Random(linktype)
    packets = [
        (_damage(rng.choice(good), rng) or b"\r", rng.choice(list(PacketDirection)))
        for _ in range(400)
    ]
    _tap_capture(tmp_path / "damaged.pcapng", linktype, packets)
    prefix = "sj300" if linktype == 147 else "fr700"
    rows = decode(tmp_path / "damaged.pcapng", [f"{prefix}.type"], tmp_path / "home")
    assert len(rows) == len(packets)
    assert {row[f"{prefix}.type"] for row in rows} <= {
        "request", "reply", "echo", "noise", "host_answer"
    }  # fmt: skip
    assert all(row[f"{prefix}.type"] for row in rows)
