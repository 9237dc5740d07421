"""The parameter snapshot file of ``sj300 params``: JSON, raw integers.

Format (version 1)::

    {
      "format": "sj300-params",
      "version": 1,
      "node": 1,                      the drive it was read from
      "url": "tcp://10.0.0.5:4001",   the bus it was read over (informative)
      "created": "2025-01-31T12:00:00+00:00",
      "parameters": {"F001": 5000, "F002": 3000, ...},
      "absent": ["P031"]              codes the drive answered NAK 16 for
    }

Values are the raw integers of commands 06 / 07 (F002 = 30.00 s is 3000),
not engineering values: a raw value round-trips exactly, whatever scale a
catalogue (or a firmware) gives the code, and a code the catalogue does not
know is kept too. ``sj300 read --raw`` shows the same numbers. Readers
ignore keys they do not know; ``created`` and ``absent`` are optional.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final

from ..sj300._constants import MAX_NODE, MIN_NODE
from ..sj300._parameters import RAW_VALUE_MAX, RAW_VALUE_MIN, normalize_code
from ..wire._errors import LocalProtocolError
from ._errors import CliError

__all__ = ["FORMAT", "VERSION", "Snapshot"]

FORMAT: Final = "sj300-params"
VERSION: Final = 1


@dataclass(frozen=True, slots=True)
class Snapshot:
    """A drive's parameters as a backup holds them."""

    node: int
    url: str
    #: Raw values by upper-case code, in the order they were read.
    parameters: dict[str, int]
    #: Codes the drive does not have (NAK 16 when read).
    absent: tuple[str, ...] = ()
    #: When the backup was taken (ISO 8601), if known.
    created: str | None = field(default=None)

    def to_json(self) -> dict[str, Any]:
        """The file's JSON object."""
        return {
            "format": FORMAT,
            "version": VERSION,
            "node": self.node,
            "url": self.url,
            "created": self.created or datetime.now(UTC).isoformat(timespec="seconds"),
            "parameters": self.parameters,
            "absent": list(self.absent),
        }

    def save(self, path: Path) -> None:
        """Write the file atomically: a reader never sees half of it.

        Raises:
            OSError: the file cannot be written.
        """
        text = json.dumps(self.to_json(), indent=2) + "\n"
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
            os.chmod(tmp, 0o644)  # mkstemp's 0600 is for secrets; a backup is not one
            os.replace(tmp, path)
        except BaseException:
            os.unlink(tmp)
            raise

    @classmethod
    def load(cls, path: Path) -> Snapshot:
        """Read and check a snapshot file.

        Raises:
            CliError: it cannot be read or is not a valid version-1 snapshot.
        """
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise CliError(f"{path}: {exc.strerror or exc}") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise CliError(f"{path}: not JSON ({exc})") from None
        try:
            return cls._from_json(data)
        except (KeyError, TypeError, ValueError) as exc:
            raise CliError(f"{path}: not an {FORMAT} version {VERSION} file: {exc}") from None

    @classmethod
    def _from_json(cls, data: Any) -> Snapshot:
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ValueError(f'no "format": "{FORMAT}"')
        if data.get("version") != VERSION:
            raise ValueError(f"version {data.get('version')!r} is not {VERSION}")
        node = data["node"]
        if type(node) is not int or not MIN_NODE <= node <= MAX_NODE:
            raise ValueError(f"node {node!r} is not {MIN_NODE}..{MAX_NODE}")
        parameters: dict[str, int] = {}
        for code, raw in dict(data["parameters"]).items():
            if type(raw) is not int or not RAW_VALUE_MIN <= raw <= RAW_VALUE_MAX:
                raise ValueError(f"{code}: {raw!r} is not a raw value 0..{RAW_VALUE_MAX}")
            parameters[_code(code)] = raw
        absent = tuple(_code(code) for code in data.get("absent", ()))
        created = data.get("created")
        return cls(node, str(data.get("url", "")), parameters, absent, created)


def _code(code: Any) -> str:
    if not isinstance(code, str):
        raise TypeError(f"parameter code {code!r} is not a string")
    try:
        return normalize_code(code)
    except LocalProtocolError as exc:
        raise ValueError(str(exc)) from None
