"""Line settings (speed, character format) and the wire time they imply.

Sans-IO: pure arithmetic. All drives on one bus share these settings
(C071 speed, C073 data bits, C074 parity, C075 stop bits).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Literal

from ._errors import LocalProtocolError

__all__ = ["BAUDRATES", "INSTANT_LINE", "LineSettings", "Parity"]

Parity = Literal["N", "E", "O"]

#: Speeds an SJ300 supports (C071 = 03..06). Other speeds are accepted: the
#: FR-700 and many RS-485 converters use them; the drive must match the host.
BAUDRATES: Final = (2400, 4800, 9600, 19200)
#: What a UART can be asked for; anything outside is a typo, not a setting.
MIN_BAUDRATE: Final = 50
MAX_BAUDRATE: Final = 4_000_000
_PARITY_NAMES: Final = {"N": "N", "E": "E", "O": "O", "NONE": "N", "EVEN": "E", "ODD": "O"}


@dataclass(frozen=True, slots=True)
class LineSettings:
    """Speed and character format of an RS-485 line.

    ``baudrate=0`` describes an in-memory line on which bytes take no time.
    """

    baudrate: int = 19200
    bytesize: int = 8
    parity: Parity = "N"
    stopbits: int = 1

    def __post_init__(self) -> None:
        if isinstance(self.baudrate, bool) or not isinstance(self.baudrate, int):
            raise LocalProtocolError(f"baud rate must be an int, got {self.baudrate!r}")
        if self.baudrate != 0 and not MIN_BAUDRATE <= self.baudrate <= MAX_BAUDRATE:
            raise LocalProtocolError(
                f"baud rate must be {MIN_BAUDRATE}..{MAX_BAUDRATE} bps "
                f"(an SJ300 uses {', '.join(map(str, BAUDRATES))}), got {self.baudrate!r}"
            )
        if isinstance(self.bytesize, bool) or self.bytesize not in (7, 8):
            raise LocalProtocolError(f"data bits must be 7 or 8, got {self.bytesize!r}")
        if self.parity not in ("N", "E", "O"):
            raise LocalProtocolError(f"parity must be N, E or O, got {self.parity!r}")
        if isinstance(self.stopbits, bool) or self.stopbits not in (1, 2):
            raise LocalProtocolError(f"stop bits must be 1 or 2, got {self.stopbits!r}")

    @classmethod
    def parse(
        cls,
        baudrate: int | str = 19200,
        bytesize: int | str = 8,
        parity: str = "N",
        stopbits: int | str = 1,
    ) -> LineSettings:
        """Build settings from user input such as URL query values ("E", "even", "19200").

        Raises:
            LocalProtocolError: a value is not one the protocol allows.
        """
        try:
            baud, size, stop = int(baudrate), int(bytesize), int(stopbits)
        except (TypeError, ValueError):
            raise LocalProtocolError(
                f"line settings must be numbers: baudrate={baudrate!r}, "
                f"bytesize={bytesize!r}, stopbits={stopbits!r}"
            ) from None
        name = _PARITY_NAMES.get(str(parity).upper())
        if name is None:
            raise LocalProtocolError(f"parity must be N, E or O, got {parity!r}")
        return cls(baud, size, name, stop)  # type: ignore[arg-type]

    @property
    def bits_per_char(self) -> int:
        """Start bit + data bits + parity bit (if any) + stop bits."""
        return 1 + self.bytesize + (self.parity != "N") + self.stopbits

    @property
    def char_time_s(self) -> float:
        """Wire time of one character in seconds (0 on an instant line)."""
        return self.bits_per_char / self.baudrate if self.baudrate else 0.0

    def wire_time_s(self, n_bytes: int) -> float:
        """Wire time of *n_bytes* characters in seconds."""
        return n_bytes * self.char_time_s


#: An in-memory line: no wire time at all.
INSTANT_LINE: Final = LineSettings(baudrate=0)
