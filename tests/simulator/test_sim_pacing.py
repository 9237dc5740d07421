"""Wire time arithmetic and the paced line's booking (sans-IO)."""

from __future__ import annotations

import pytest

from sj300_async import LocalProtocolError
from sj300_async.simulator import LinePacing, PacedLine


@pytest.mark.parametrize(
    ("pacing", "bits"),
    [
        (LinePacing(19200, 8, "N", 1), 10),
        (LinePacing(19200, 7, "N", 1), 9),
        (LinePacing(9600, 7, "E", 1), 10),
        (LinePacing(9600, 8, "O", 2), 12),
        (LinePacing(2400, 7, "E", 2), 11),
    ],
)
def test_char_time_is_start_data_parity_stop_over_baud(pacing: LinePacing, bits: int) -> None:
    assert pacing.bits_per_char == bits
    assert pacing.char_time_s == pytest.approx(bits / pacing.baudrate)


def test_reference_figure_19200_8n1() -> None:
    # "At 19200 8N1 a character takes 0.521 ms."
    assert LinePacing().char_time_s == pytest.approx(0.000521, abs=5e-7)
    assert LinePacing().wire_time_s(446) == pytest.approx(446 * 10 / 19200)


@pytest.mark.parametrize(
    "kwargs",
    [{"baudrate": -1}, {"bytesize": 6}, {"parity": "M"}, {"stopbits": 3}, {"baudrate": 9600.0}],
)
def test_impossible_settings_are_refused(kwargs: dict[str, object]) -> None:
    with pytest.raises(LocalProtocolError):
        LinePacing(**kwargs)  # type: ignore[arg-type]


def test_an_instant_line_cannot_be_paced() -> None:
    with pytest.raises(LocalProtocolError, match="cannot be paced"):
        PacedLine(LinePacing(0))


def test_request_arrives_when_its_last_character_has_crossed() -> None:
    line = PacedLine(LinePacing(1000, 8, "N", 1))  # 10 ms a character
    [(t, piece)] = line.receive(5.0, b"\x020104")
    assert piece == b"\x020104"
    assert t == pytest.approx(5.05)
    # a write while the line is busy queues behind it
    [(t, piece)] = line.receive(5.0, b"05\r")
    assert piece == b"05\r"
    assert t == pytest.approx(5.08)


def test_request_pieces_end_after_each_cr() -> None:
    line = PacedLine(LinePacing(1000, 8, "N", 1))
    pieces = line.receive(0.0, b"\x02a\r\x02bc\rxy")
    assert [p for _, p in pieces] == [b"\x02a\r", b"\x02bc\r", b"xy"]
    assert [round(t, 6) for t, _ in pieces] == [0.03, 0.07, 0.09]


def test_reply_groups_are_never_early() -> None:
    pacing = LinePacing(19200, 8, "N", 1)
    line = PacedLine(pacing)
    data = bytes(range(100))
    groups = line.transmit(1.0, data)
    assert b"".join(g for _, g in groups) == data
    delivered = 0
    for when, group in groups:
        delivered += len(group)
        # every byte of the group has fully crossed the line by its delivery time
        assert when >= 1.0 + delivered * pacing.char_time_s - 1e-12
        # and no byte waits more than a group's worth of characters
        assert when - (1.0 + (delivered - len(group) + 1) * pacing.char_time_s) < 0.004
    assert line.free_at == pytest.approx(1.0 + 100 * pacing.char_time_s)


def test_reply_waits_for_a_busy_line() -> None:
    line = PacedLine(LinePacing(1000, 8, "N", 1), group_s=0.0)  # one character per group
    line.receive(0.0, b"0123456789")  # busy until 0.1
    groups = line.transmit(0.05, b"ab")
    assert [(round(t, 6), g) for t, g in groups] == [(0.11, b"a"), (0.12, b"b")]
