"""The parameter backup file (``sj300 params``, the workbench): JSON, values in unit and raw.

Format (version 2, what ``params backup`` writes)::

    {
      "format": "sj300-params",
      "version": 2,
      "protocol": "sj300",            the drives' protocol
      "node": 1,                      the drive it was read from
      "url": "tcp://10.0.0.5:4001",   the bus it was read over (informative)
      "taken_at": "2025-01-31T12:00:00Z",   ISO 8601, UTC
      "library_version": "0.1.0",     the sj300_async that wrote it
      "parameters": [
        {"code": "F002", "name": "acceleration time 1", "unit": "s",
         "value": 30.0, "raw": 3000},
        {"code": "P044", "name": "DeviceNet communication watchdog timer",
         "unit": "s", "value": null, "raw": null,
         "absent": "NAK 16 (abnormal parameter code or value)"},
        ...
      ]
    }

An FR-700 file (``"protocol": "fr700"``) has the same shape, one entry per
number the link addresses, Pr.0..Pr.999::

      "parameters": [
        {"code": "Pr.7", "name": "acceleration time", "unit": "s",
         "value": 5.0, "raw": 50},
        {"code": "Pr.13", "name": null, "unit": null, "value": null,
         "raw": 50},
        {"code": "Pr.14", "name": null, "unit": null, "value": null,
         "raw": null, "absent": "NAK B (instruction code error)"},
        ...

The file is the drives' protocol's: codes, names, units, the node's range
and the raw values' come from the protocol's profile
(:class:`~sj300_async.profiles.Profile`), and a file of one protocol is
never read as another's. Entries come in the order of the codes a backup
reads (:meth:`~sj300_async.profiles.ParameterCatalogue.addressable`: the
SJ300 function-code table, the FR-700's numbers; codes it lacks last,
sorting is stable). ``raw`` is the integer the drive holds (SJ300 commands
06 / 07: F002 = 30.00 s is 3000; FR-700 Pr.7 = 5.0 s is 50) and the one
number ``params restore`` writes: it round-trips exactly, whatever scale a
catalogue (or a firmware) gives the code, and a code the catalogue does not
know is kept too. ``name``, ``unit`` and ``value`` (raw scaled by the
catalogue of the version that wrote the file) are for people and other
tools; a reader takes ``raw`` and ignores them, so a hand edit must change
``raw``. A code the protocol addresses but the catalogue does not describe
(most FR-700 numbers: the library models a few dozen of several hundred)
has ``name``, ``unit`` and ``value`` null: its scale is unknown, and a raw
50 is not 50 of anything. A code the drive refused (SJ300 NAK 16: its
firmware lacks it; FR-700 NAK B: the model has no such number) has ``raw``
and ``value`` null and the reason in ``absent``.

Version 1 files (raw integers only: ``"parameters": {"F002": 3000, ...}``,
``"absent": ["P031"]``, ``"created"`` for the time, no protocol) are still
read: only ``params`` wrote them, when it talked to the default protocol's
drives only (SJ300), so that is their protocol. Nothing is lost by reading
them; a new backup writes version 2. Readers ignore keys they do not know.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final

from ..bus import DEFAULT_PROTOCOL
from ..version import __version__
from ..wire import LocalProtocolError
from ._profile import ParameterSpec, Profile

__all__ = [
    "BACKUP_FORMAT",
    "BACKUP_VERSION",
    "BackupFormatError",
    "ParameterBackup",
    "catalogued",
    "parameter_code",
    "utc_now",
]

FORMAT: Final = "sj300-params"
#: The version a backup writes.
VERSION: Final = 2
BACKUP_FORMAT: Final = FORMAT
BACKUP_VERSION: Final = VERSION
#: The versions a restore or diff reads.
READABLE_VERSIONS: Final = (1, 2)
#: The protocol of a version 1 file: it names none, and predates every other protocol.
_V1_PROTOCOL: Final = DEFAULT_PROTOCOL
#: The reason a version 1 file gives for an absent code (it recorded none).
_V1_ABSENT: Final = "absent (version 1 file: no reason recorded)"


def catalogued(profile: Profile, code: str) -> ParameterSpec | None:
    """*code*'s catalogue entry, None for a code the catalogue does not describe."""
    try:
        return profile.parameters.spec(code)
    except LocalProtocolError:
        return None


def parameter_code(profile: Profile, text: str) -> str:
    """The protocol's code for *text*: a catalogued one, or any code a backup reads.

    ``"f002"`` is ``F002``, ``"pr 500"`` ``Pr.500`` (uncatalogued, but an
    FR-700 drive may have it).

    Raises:
        LocalProtocolError: neither (the catalogue's reason).
    """
    try:
        return profile.parameters.spec(text).code
    except LocalProtocolError:
        code = _addressable(profile).get(_key(text))
        if code is None:
            raise
        return code


def _key(text: str) -> str:
    return "".join(text.split()).replace(".", "").upper()


_ADDRESSABLE: dict[str, dict[str, str]] = {}


def _addressable(profile: Profile) -> dict[str, str]:
    """The codes a backup of *profile*'s drives reads, by :func:`_key`."""
    found = _ADDRESSABLE.get(profile.name)
    if found is None:
        codes = profile.parameters.addressable()
        found = _ADDRESSABLE[profile.name] = {_key(code): code for code in codes}
    return found


def utc_now() -> str:
    """The current time, ISO 8601 in UTC to the second: ``2025-01-31T12:00:00Z``."""
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


class BackupFormatError(LocalProtocolError):
    """A backup that cannot be read: not JSON, not this format, or another protocol's."""


@dataclass(frozen=True, slots=True)
class ParameterBackup:
    """A drive's parameters as a backup holds them."""

    node: int
    url: str
    #: Raw values by upper-case code, in the order they were read.
    parameters: dict[str, int]
    #: Codes the drive does not have (NAK 16 when read), with the reason.
    absent: Mapping[str, str] = field(default_factory=dict)
    #: When the backup was taken (ISO 8601, UTC), if known.
    taken_at: str | None = None
    #: The drives' protocol.
    protocol: str = DEFAULT_PROTOCOL
    #: The library version that wrote the file, if known.
    library_version: str | None = None
    #: The file's format version (a new snapshot: :data:`VERSION`).
    version: int = VERSION

    def to_json(self, profile: Profile) -> dict[str, Any]:
        """The file's JSON object (version 2); *profile* is the drives' protocol's."""
        readings: dict[str, int | str] = {**self.parameters, **self.absent}
        position = {code: i for i, code in enumerate(profile.parameters.addressable())}
        entries: list[dict[str, Any]] = []
        for code in sorted(readings, key=lambda c: position.get(c, len(position))):
            info = catalogued(profile, code)
            reading = readings[code]
            entry: dict[str, Any] = {
                "code": code,
                "name": None if info is None else info.name,
                "unit": None if info is None else info.unit,
            }
            if isinstance(reading, int):
                value = None if info is None else info.from_raw(reading)
                entry |= {"value": value, "raw": reading}
            else:
                entry |= {"value": None, "raw": None, "absent": reading}
            entries.append(entry)
        return {
            "format": FORMAT,
            "version": VERSION,
            "protocol": self.protocol,
            "node": self.node,
            "url": self.url,
            "taken_at": self.taken_at or utc_now(),
            "library_version": self.library_version or __version__,
            "parameters": entries,
        }

    def save(self, path: Path, profile: Profile) -> None:
        """Write the file atomically: a reader never sees half of it.

        Raises:
            OSError: the file cannot be written.
        """
        text = json.dumps(self.to_json(profile), indent=2) + "\n"
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
    def load(cls, path: Path, profile: Profile) -> ParameterBackup:
        """Read and check a backup file of *profile*'s protocol's drives.

        Raises:
            BackupFormatError: it cannot be read, is not a valid version 1 or 2
                backup, or holds another protocol's parameters (the message
                starts with the file's name).
        """
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise BackupFormatError(f"{path}: {exc.strerror or exc}") from None
        return cls.from_bytes(data, profile, source=str(path))

    @classmethod
    def from_bytes(cls, data: bytes | str, profile: Profile, *, source: str) -> ParameterBackup:
        """Read and check a backup's text (an upload), named *source* in errors.

        Raises:
            BackupFormatError: see :meth:`load`.
        """
        try:
            parsed = json.loads(data)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise BackupFormatError(f"{source}: not JSON ({exc})") from None
        try:
            _check_header(parsed)
        except ValueError as exc:
            raise BackupFormatError(f"{source}: not an {FORMAT} file: {exc}") from None
        protocol = parsed.get("protocol", _V1_PROTOCOL)
        if protocol != profile.name:
            model = profile.model
            raise BackupFormatError(
                f"{source}: a backup of {protocol} drives: its codes are not {model} parameters, "
                f"so it is never restored onto or compared with an {model} drive"
            )
        try:
            return _Reader(profile).snapshot(parsed)
        except (KeyError, TypeError, ValueError) as exc:
            version = parsed["version"]
            raise BackupFormatError(
                f"{source}: not an {FORMAT} version {version} file: {exc}"
            ) from None


class _Reader:
    """A file's entries checked against the drives' protocol's profile."""

    def __init__(self, profile: Profile) -> None:
        self.profile = profile

    def snapshot(self, data: dict[str, Any]) -> ParameterBackup:
        node = data["node"]
        low, high = self.profile.node_range
        if type(node) is not int or not low <= node <= high:
            raise ValueError(f"{self.profile.node_noun} {node!r} is not {low}..{high}")
        url = str(data.get("url", ""))
        if data["version"] == 1:
            parameters = {
                self._code(code): self._raw(code, raw)
                for code, raw in dict(data["parameters"]).items()
            }
            absent = dict.fromkeys(
                (self._code(code) for code in data.get("absent", ())), _V1_ABSENT
            )
            return ParameterBackup(node, url, parameters, absent, _text(data, "created"), version=1)
        parameters = {}
        absent = {}
        entries = data["parameters"]
        if not isinstance(entries, list):
            raise TypeError('"parameters" is not a list')
        for entry in entries:
            if not isinstance(entry, dict):
                raise TypeError(f"parameter entry {entry!r} is not an object")
            code = self._code(entry["code"])
            if "absent" in entry and entry.get("raw") is None:
                absent[code] = str(entry["absent"])
            else:
                parameters[code] = self._raw(code, entry["raw"])
        return ParameterBackup(
            node,
            url,
            parameters,
            absent,
            _text(data, "taken_at"),
            self.profile.name,
            _text(data, "library_version"),
            version=2,
        )

    def _code(self, code: Any) -> str:
        if not isinstance(code, str):
            raise TypeError(f"parameter code {code!r} is not a string")
        try:
            return parameter_code(self.profile, code)
        except LocalProtocolError as exc:
            raise ValueError(str(exc)) from None

    def _raw(self, code: Any, raw: Any) -> int:
        low, high = self.profile.parameters.raw_range
        if type(raw) is not int or not low <= raw <= high:
            raise ValueError(f"{code}: {raw!r} is not a raw value {low}..{high}")
        return raw


def _check_header(data: Any) -> None:
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ValueError(f'no "format": "{FORMAT}"')
    version = data.get("version")
    if version not in READABLE_VERSIONS:
        readable = " or ".join(map(str, READABLE_VERSIONS))
        raise ValueError(f"version {version!r} is not {readable}")
    protocol = data.get("protocol", _V1_PROTOCOL)
    if not isinstance(protocol, str):
        raise ValueError(f"protocol {protocol!r} is not a name")


def _text(data: dict[str, Any], key: str) -> str | None:
    value = data.get(key)
    return None if value is None else str(value)
