"""The FR-700 fault history (H74..H77): the reference's vectors, the table, a simulated drive.

The reference (``mitsubishi-fr700.md``, "Fault history"): H74's low byte is
the most recent trip and its high byte the one before, then H75, H76, H77;
empty slots read 00; the manual's own example H30A0 is most recent E.OPT,
then E.THT; an unlisted byte is "unknown (0xNN)", never an error.
"""

from __future__ import annotations

import asyncio

import pytest

import sj300_async as sj
from sj300_async import fr700
from sj300_async.simulator.fr700 import FaultCode, Fr700SimulatedBus

from .test_fr700_drive import fr700_bus


def test_the_manuals_example_word_is_most_recent_opt_then_tht() -> None:
    history = fr700.decode_fault_history([0x30A0, 0, 0, 0])
    assert [f.display for f in history.faults] == ["E.OPT", "E.THT"]
    assert history.latest == fr700.Fr700Fault(0xA0, "E.OPT", "option fault")
    assert str(history.faults[1]) == "E.THT inverter overload trip (electronic thermal relay)"


def test_eight_trips_come_newest_first_across_the_four_words() -> None:
    words = [0x1110, 0x2012, 0x2221, 0x3130]  # H74..H77
    codes = [f.code for f in fr700.decode_fault_history(words).faults]
    assert codes == [0x10, 0x11, 0x12, 0x20, 0x21, 0x22, 0x30, 0x31]
    assert len(codes) == fr700.FAULT_HISTORY_DEPTH


def test_a_cleared_drive_has_no_trips_and_an_unlisted_code_is_kept_unnamed() -> None:
    assert fr700.decode_fault_history([0, 0, 0, 0]).faults == ()
    assert fr700.decode_fault_history([0, 0, 0, 0]).latest is None
    (unknown,) = fr700.decode_fault_history([0x00E9, 0, 0, 0]).faults
    assert (unknown.display, unknown.meaning) == ("unknown (0xE9)", None)
    assert str(unknown) == "unknown (0xE9)"


@pytest.mark.parametrize(("code", "display"), [(0xF5, "E.5"), (0xFB, "E.11"), (0xFD, "E.13")])
def test_e_n_codes_are_hf0_plus_n(code: int, display: str) -> None:
    assert fr700.Fr700Fault.of(code).display == display


@pytest.mark.parametrize("words", [[0, 0, 0], [0, 0, 0, 0, 0], [0x10000, 0, 0, 0], [-1, 0, 0, 0]])
def test_anything_but_four_words_is_a_protocol_error(words: list[int]) -> None:
    with pytest.raises(sj.RemoteProtocolError):
        fr700.decode_fault_history(words)


async def test_a_simulated_drive_s_trips_read_back_newest_first() -> None:
    async with fr700_bus() as bus:
        sim = bus.simulator
        assert isinstance(sim, Fr700SimulatedBus)
        drive = bus.drive(1)
        assert (await drive.read_fault_history()).faults == ()
        for code in (FaultCode.OC1, FaultCode.THT, FaultCode.PUE):
            sim.drives[1].trip(code, now=asyncio.get_running_loop().time())
            await drive.reset()
            await drive.read_status()  # the reset has no reply: a round trip shows it done
        history = await drive.read_fault_history()
        assert [f.display for f in history.faults] == ["E.PUE", "E.THT", "E.OC1"]
        assert [f.code for f in history.faults] == list(sim.drives[1].fault_history)
