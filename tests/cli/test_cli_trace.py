"""``--trace``: every frame on stderr with its time, direction, hex and meaning."""

from __future__ import annotations

import io
import re
from typing import Any, cast

from sj300_async.bus import Dialect, TraceRecord, get_dialect
from sj300_async.cli._trace import FrameTracer, describe_bytes, request_describer
from sj300_async.fr700 import Fr700Dialect
from sj300_async.fr700 import _requests as fr700_requests
from sj300_async.wire import BadFrame, BadFrameReason, Discarded, DiscardReason

from .clirun import TcpSim, sj300

_LINE = re.compile(r" *(?P<t>\d+\.\d{3}) (?P<dir>→ tx|← rx)  (?P<hex>[0-9A-F ]+?)  (?P<meaning>.+)")


def _hex(frame: bytes) -> str:
    return frame.hex(" ").upper()


async def test_a_status_read_traces_both_requests_and_replies(tcp_sim: TcpSim) -> None:
    plain = await sj300("status", "-n", "2", "--url", tcp_sim.url)
    traced = await sj300("status", "-n", "2", "--url", tcp_sim.url, "--trace")
    assert traced.code == 0, traced.err
    assert traced.out == plain.out  # the trace goes to stderr only
    lines = traced.err.splitlines()
    matches = [_LINE.fullmatch(line) for line in lines]
    assert all(matches), lines
    found = [m for m in matches if m is not None]
    assert [m["dir"] for m in found][:2] == ["→ tx", "← rx"]
    times = [float(m["t"]) for m in found]
    assert times == sorted(times)
    assert 0 <= times[0] < 10
    tx = [m for m in found if m["dir"] == "→ tx"]
    assert [(m["hex"], m["meaning"]) for m in tx] == [
        (_hex(b"\x02020406\r"), "node 02 command 04 read status"),
        (_hex(b"\x02020301\r"), "node 02 command 03 read monitor"),
        (_hex(b"\x020206F00173\r"), "node 02 command 06 read parameter F001"),
    ]
    rx = [m for m in found if m["dir"] == "← rx"]
    assert rx[0]["hex"].startswith("02 30 32 ")  # STX "02"
    completed = [m["meaning"] for m in rx if m["meaning"] != "…"]
    assert len(completed) == 3
    assert [m.split(" data ")[0] for m in completed] == ["node 02"] * 2 + ["node 02 ACK +"]
    assert not any("refused" in m for m in completed)  # a healthy line: nothing marked early


async def test_a_nak_and_options_before_the_command(tcp_sim: TcpSim) -> None:
    result = await sj300("--trace", "--url", tcp_sim.url, "read", "F999")
    assert result.code == 1
    lines = result.err.splitlines()
    assert re.fullmatch(r" *\d+\.\d{3} → tx  .*  node 01 command 06 read parameter F999", lines[0])
    assert lines[1].endswith("node 01 NAK 16 (abnormal parameter code or value)"), lines
    assert lines[-1].startswith("sj300 read: error: F999: node 01 answered NAK 16")


async def test_a_broadcast_and_a_write_on_the_simulator() -> None:
    result = await sj300("stop", "--all", "--sim", "--trace")
    assert result.code == 0, result.err
    (line,) = result.err.splitlines()  # a broadcast has no reply
    assert line.endswith("broadcast command 00 run 0"), line


def test_bad_frames_and_discarded_bytes_print_their_reason() -> None:
    out = io.StringIO()
    tracer = FrameTracer(get_dialect("sj300"), origin=100.0, stream=out)
    events = (
        Discarded(DiscardReason.GARBAGE, b"xy"),
        BadFrame(BadFrameReason.BAD_BCC, b"0100FF", 1),
        BadFrame(BadFrameReason.BAD_NODE, b"zz"),
    )
    tracer(TraceRecord(100.0024, "rx", b"xy\x020100FF\r", events))
    tracer(TraceRecord(100.25, "rx", b"\x0201"))  # a reply's first part
    first, second = out.getvalue().splitlines()
    assert first == (
        f"   0.002 ← rx  {_hex(b'xy' + bytes([2]) + b'0100FF' + bytes([13]))}  "
        "discarded 2 byte(s): garbage; bad frame from node 01: bad BCC; bad frame: bad node"
    )
    assert second == "   0.250 ← rx  02 30 31  …"


def test_a_frame_the_request_parser_refuses_is_named() -> None:
    describe = request_describer(get_dialect("sj300"))
    assert describe(b"\x0201049\r") == "bad request: too short"


def test_fr700_requests_are_decoded_with_the_line_options() -> None:
    factory = Fr700Dialect().options
    describe = request_describer(get_dialect("fr700"))
    status = fr700_requests.read(0, "H7A", options=factory)
    assert describe(status.frame) == "station 00 instruction H7A status"
    run = fr700_requests.write(3, "HFA", 2, options=factory)
    assert describe(run.frame) == "station 03 instruction HFA run command 02"
    url_options = {"wait_field": "0", "terminator": "none"}
    describe_plain = request_describer(get_dialect("fr700").configure(url_options))
    plain = Fr700Dialect(wait_field=False, terminator="").options
    frame = fr700_requests.read(1, "H07", options=plain).frame
    assert describe_plain(frame) == "station 01 instruction H07 read parameter"


def test_another_protocol_shows_its_characters() -> None:
    assert describe_bytes(b"\x02AB\x7f\r") == "<STX>AB.<CR>"


def test_a_meaning_that_fails_never_breaks_the_command() -> None:
    class Broken(Fr700Dialect):
        def describe(self, reply: object) -> str:
            raise ValueError("nope")

    out = io.StringIO()
    broken = cast(Dialect[Any, Any], Broken())
    FrameTracer(broken, origin=0.0, stream=out)(TraceRecord(1.0, "rx", b"\x06", (object(),)))
    assert out.getvalue() == "   1.000 ← rx  06  (not decoded: ValueError: nope)\n"
