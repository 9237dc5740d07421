"""Which trip a drive is in, as the commands name it: ``E07 over-voltage``.

A drive's status says only *that* it is tripped. The trip itself is the
newest entry of its trip history: an SJ300's command 05 (a trip while
tripped is not recorded, so the newest record is the present trip), an
FR-700's fault history H74 (low byte: the latest fault). SJ300 codes carry
their meaning (:class:`~sj300_async.sj300.TripCode`); the FR-700 reference
lists no fault codes, so an FR-700 fault is shown as its number (``fault
H10``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..fr700._codes import Fr700Instruction
from ..fr700._drive import Fr700Drive
from ..sj300._codes import TripCode
from ..sj300._drive import Drive

__all__ = ["Trip", "fr700_fault", "latest_trip", "sj300_trip"]


@dataclass(frozen=True, slots=True)
class Trip:
    """A trip as the commands show it."""

    code: str  #: as the drive shows it: ``"E07"``; an FR-700 fault ``"H10"``
    number: int  #: the trip factor / fault code
    name: str | None  #: the codec's name (``"OVER_VOLTAGE"``); None when the reference has none
    meaning: str | None  #: ``"over-voltage"``; None when the reference gives none

    def __str__(self) -> str:
        if self.meaning is None:
            return f"fault {self.code}"
        return f"{self.code} {self.meaning}"

    def as_json(self) -> dict[str, Any]:
        """``{"code": "E07", "number": 7, "name": "OVER_VOLTAGE", "meaning": "over-voltage"}``."""
        return {
            "code": self.code,
            "number": self.number,
            "name": self.name,
            "meaning": self.meaning,
        }


def sj300_trip(number: int) -> Trip:
    """An SJ300 trip factor with its meaning (an unlisted one as ``unknown trip``)."""
    code = TripCode(number)
    return Trip(code.error_code, int(code), code.name, code.description)


def fr700_fault(number: int) -> Trip:
    """An FR-700 fault code: its number only (the reference lists no meanings)."""
    return Trip(f"H{number:02X}", number, None, None)


async def latest_trip(drive: Drive | Fr700Drive) -> Trip | None:
    """The drive's newest trip (None when its history is empty).

    Raises:
        SJ300Error: the history could not be read.
    """
    if isinstance(drive, Fr700Drive):
        latest = await drive.read(Fr700Instruction.FAULT_HISTORY) & 0xFF
        return fr700_fault(latest) if latest else None
    trips = (await drive.read_trip_history()).trips
    return sj300_trip(trips[0].trip_factor) if trips else None
