"""Configuration files that say where they are wrong: TOML read with line numbers.

The gateway's schema (:mod:`._config`) and every northbound's own section
are validated through :class:`ConfigTable`: typed getters whose refusals
are one :class:`GatewayConfigError` naming the file, the line and the
dotted key, the way a compiler reports::

    gateway.toml:12: lines[1].nodes: node 40 is outside 1..32

Decisions:

- A table's unknown keys are checked before its values, so a misspelt key
  is reported as itself (with a did-you-mean), not as the required key it
  was meant to be.
- tomllib gives no positions, so :func:`_key_lines` scans the raw text for
  table headers and ``key =`` lines. It only places errors: its limits
  (documented there) can cost a line number, never change a verdict.
- A configuration built from command-line flags goes through the same
  rules, with the keys renamed to the flags in messages
  (``lines[0].nodes`` -> ``--nodes``): one set of rules, one set of messages.
"""

from __future__ import annotations

import difflib
import errno
import json
import math
import os
import re
import stat
import tomllib
from collections.abc import Mapping, Sequence
from datetime import date, datetime, time
from pathlib import Path
from typing import Final, TypeVar

from ..wire import LocalProtocolError
from ._model import Endpoint, parse_endpoint

__all__ = [
    "COMMAND_LINE",
    "ConfigContext",
    "ConfigTable",
    "GatewayConfigError",
    "or_default",
    "read_toml",
    "type_name",
    "unknown_choice",
]

T = TypeVar("T")

#: The source of a configuration built from the command line's flags.
COMMAND_LINE: Final = "<command line>"
_BARE_KEY: Final = re.compile(r"[A-Za-z0-9_-]+\Z")
_TOML_POSITION: Final = re.compile(r"\s*\((?:at line (\d+), column (\d+)|at end of document)\)\Z")


class GatewayConfigError(LocalProtocolError):
    """A configuration the gateway refuses: where (file, line, key) and why.

    ``str()`` is one line, ``SOURCE[:LINE]: [KEY: ]REASON``, the form editors
    and CI logs recognise.
    """

    def __init__(self, source: str, line: int | None, key: str | None, reason: str) -> None:
        # All four in args: the error pickles and reprs as it was built.
        super().__init__(source, line, key, reason)
        #: The file name as given, or ``"<command line>"``.
        self.source = source
        #: 1-based line in the file (None: unknown, or not from a file).
        self.line = line
        #: The dotted key, e.g. ``lines[1].writes[0].nodes``, or the flag.
        self.key = key
        self.reason = reason

    def __str__(self) -> str:
        where = self.source if self.line is None else f"{self.source}:{self.line}"
        return f"{where}: {self.key}: {self.reason}" if self.key else f"{where}: {self.reason}"


#: The largest configuration file read: a plant of 2,048 drives writes about 0.3 MB.
MAX_CONFIG_BYTES: Final = 16 * 2**20


def read_toml(path: str | os.PathLike[str]) -> tuple[str, str]:
    """The text of the configuration file *path*, and its name as given.

    Raises:
        GatewayConfigError: the file cannot be read, or is not UTF-8 text.
    """
    source = os.fspath(path)
    try:
        kind = os.stat(source).st_mode
        if stat.S_ISDIR(kind):
            raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), source)
        if not stat.S_ISREG(kind):  # a FIFO would block the read, a device never end it
            raise GatewayConfigError(source, None, None, "not a regular file")
        with Path(source).open("rb") as file:
            raw = file.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise GatewayConfigError(source, None, None, exc.strerror or str(exc)) from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise GatewayConfigError(
            source, None, None, f"larger than {MAX_CONFIG_BYTES // 2**20} MiB: not a configuration"
        )
    try:
        return raw.decode("utf-8-sig"), source  # tolerate the BOM some Windows editors write
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise GatewayConfigError(source, line, None, f"not UTF-8 text: {exc.reason}") from None


def parse_toml(text: str, source: str) -> object:
    """The data of the TOML *text*.

    Raises:
        GatewayConfigError: not TOML; the message places tomllib's error.
    """
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise _syntax_error(source, text, exc) from None
    except RecursionError:  # tomllib recurses into nested arrays and tables
        raise GatewayConfigError(source, None, None, "invalid TOML: nested too deeply") from None
    except ValueError as exc:  # an integer of more than 4,300 digits (int's own limit)
        raise GatewayConfigError(source, None, None, f"invalid TOML: {exc}") from None


# -- where errors are ----------------------------------------------------------------------


class ConfigContext:
    """Where the values come from: turns a key and a reason into a :class:`GatewayConfigError`."""

    def __init__(self, source: str, text: str = "", rename: Mapping[str, str] | None = None):
        self.source = source
        self._text = text
        self._rename = rename or {}
        self._lines: dict[str, int] | None = None

    def display(self, key: str) -> str:
        """How messages name *key*: the flag it came from on the command line, else itself."""
        return self._rename.get(key, key)

    def error(self, key: str, reason: str) -> GatewayConfigError:
        if self._lines is None:  # scanned on the first error only
            self._lines = _key_lines(self._text)
        return GatewayConfigError(
            self.source, _line_of(self._lines, key), self._rename.get(key, key) or None, reason
        )


def _syntax_error(source: str, text: str, exc: tomllib.TOMLDecodeError) -> GatewayConfigError:
    """tomllib's message, with its ``(at line N, column M)`` moved to where our format puts it."""
    message = str(exc)
    found = _TOML_POSITION.search(message)
    if found is None:
        return GatewayConfigError(source, None, None, f"invalid TOML: {message}")
    if found[1] is None:  # "at end of document": the last line
        line, where = text.count("\n") + 1, "at end of file"
    else:
        line, where = int(found[1]), f"column {found[2]}"
    return GatewayConfigError(
        source, line, None, f"invalid TOML: {message[: found.start()]} ({where})"
    )


# The locator. It reads the text line by line, tracking the current table:
# ``[name]`` and ``[[name]]`` headers (an array of tables counts its elements,
# per parent, so the second ``[[lines.writes]]`` under the second ``[[lines]]``
# is ``lines[1].writes[1]``) and ``key = value`` lines, skipping the
# continuation lines of a value whose brackets or braces are still open.
# Limits, all costing only precision (an error then points at the enclosing
# table, or at the first line of the value):
# - the lines inside a multi-line string are read like any others;
# - a quoted key containing "." or "=", or a header containing "]", is misread;
# - keys inside an inline table or an array of inline tables are not
#   located: their errors point at the line of the key holding the value.
_HEADER: Final = re.compile(r"\s*(\[\[?)\s*([^\[\]]+?)\s*\]\]?\s*(?:#.*)?\Z")
_KEY: Final = re.compile(r"\s*([A-Za-z0-9_\-. \"']+?)\s*=")
_STRING: Final = re.compile(r"\"(?:[^\"\\]|\\.)*\"|'[^']*'")
_LAST_PART: Final = re.compile(r"[.\[][^.\[]*\Z")


def _key_lines(text: str) -> dict[str, int]:
    """Map each key path (``lines[1].writes[0].nodes``) and table to the line that writes it."""
    found: dict[str, int] = {}
    counts: dict[str, int] = {}  # array-of-tables path → elements so far
    table = ""
    depth = 0  # brackets and braces still open in a value spanning lines
    for number, raw in enumerate(text.split("\n"), start=1):  # tomllib counts "\n" only
        if depth > 0:
            depth += _balance(raw)
        elif header := _HEADER.match(raw):
            table = _table_path(header[2], counts, is_array=header[1] == "[[")
            found.setdefault(table, number)
        elif key := _KEY.match(raw):
            path = table
            for part in _dotted(key[1]):
                path = _join(path, part)
                # A dotted key also writes each table it names (``modbus.listen``
                # writes ``modbus``): an error about one of them points here.
                found.setdefault(path, number)
            depth = _balance(raw[key.end() :])
    return found


def _table_path(name: str, counts: dict[str, int], *, is_array: bool) -> str:
    """The key path of a table header; an array's parent is its last element so far."""
    path = ""
    *parents, last = _dotted(name)
    for part in parents:
        path = _join(path, part)
        if path in counts:
            path = f"{path}[{counts[path] - 1}]"
    path = _join(path, last)
    if is_array:
        counts[path] = counts.get(path, 0) + 1
        path = f"{path}[{counts[path] - 1}]"
    return path


def _dotted(name: str) -> list[str]:
    return [part.strip().strip("\"'") for part in name.split(".")]


def _balance(code: str) -> int:
    """Brackets and braces opened minus closed, outside strings and comments."""
    code = _STRING.sub("", code).partition("#")[0]
    return code.count("[") + code.count("{") - code.count("]") - code.count("}")


def _line_of(lines: Mapping[str, int], key: str) -> int | None:
    """The line of *key*, else of its nearest enclosing table that has one."""
    while key not in lines:
        parent = _LAST_PART.sub("", key)
        if parent == key:  # a top-level key that is not written anywhere
            return None
        key = parent
    return lines[key]


def _join(path: str, name: str) -> str:
    """``lines[0]`` + ``url`` → ``lines[0].url``; a name that is not a bare key is quoted."""
    part = name if _BARE_KEY.match(name) else json.dumps(name)
    return f"{path}.{part}" if path else part


# -- typed reading of one table --------------------------------------------------------------


def type_name(value: object) -> str:
    """The TOML name of *value*'s type, for "expected a number, got string"."""
    for kind, name in (
        (bool, "boolean"),  # before int: a bool is an int to Python, never to TOML
        (int, "integer"),
        (float, "float"),
        (str, "string"),
        (list, "array"),
        (dict, "table"),
        (datetime, "date-time"),  # before date, its base class
        (date, "date"),
        (time, "time"),
    ):
        if isinstance(value, kind):
            return name
    return type(value).__name__


def unknown_choice(kind: str, value: str, choices: Sequence[str]) -> str:
    """``unknown key 'listn' (did you mean 'listen'?)``, else the choices."""
    close = difflib.get_close_matches(value, choices, n=1)
    hint = f"did you mean {close[0]!r}?" if close else f"use {', '.join(choices)}"
    return f"unknown {kind} {value!r} ({hint})"


def or_default(value: T | None, default: T) -> T:
    return default if value is None else value


class ConfigTable:
    """One table being validated: typed getters whose errors name the key; no unknown keys."""

    def __init__(self, ctx: ConfigContext, path: str, data: object, allowed: Sequence[str]) -> None:
        self.ctx = ctx
        self.path = path
        if not isinstance(data, dict):
            raise ctx.error(path, f"expected a table, got {type_name(data)}")
        self.data: dict[str, object] = data
        for name in data:
            if name not in allowed:
                raise self.error(name, unknown_choice("key", name, allowed))

    def error(self, name: str, reason: str) -> GatewayConfigError:
        return self.ctx.error(_join(self.path, name) if name else self.path, reason)

    def has(self, name: str) -> bool:
        return name in self.data

    def required(self, name: str) -> object:
        if name not in self.data:
            raise self.error(name, f"missing required key {name!r}")
        return self.data[name]

    def string(self, name: str) -> str | None:
        value = self.data.get(name)  # TOML has no null: None means absent
        if value is None or isinstance(value, str):
            return value
        raise self.error(name, f"expected a string, got {type_name(value)}")

    def required_string(self, name: str) -> str:
        self.required(name)
        return or_default(self.string(name), "")

    def boolean(self, name: str) -> bool | None:
        value = self.data.get(name)
        if value is None or isinstance(value, bool):
            return value
        raise self.error(name, f"expected true or false, got {type_name(value)}")

    def integer(self, name: str) -> int | None:
        value = self.data.get(name)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(name, f"expected an integer, got {type_name(value)}")
        return value

    def number(self, name: str, *, minimum: float, inclusive: bool) -> float | None:
        """A finite int or float >= *minimum* (> when not *inclusive*); None when absent."""
        value = self.data.get(name)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(name, f"expected a number, got {type_name(value)}")
        try:
            number = float(value)
        except OverflowError:  # TOML integers are unbounded to tomllib
            number = math.inf
        if not math.isfinite(number):
            raise self.error(name, f"expected a finite number, got {value}")
        if number < minimum or (number == minimum and not inclusive):
            bound = ">=" if inclusive else ">"
            raise self.error(name, f"must be {bound} {minimum:g}, got {number:g}")
        return number

    def strings(self, name: str) -> tuple[str, ...] | None:
        value = self.data.get(name)
        if value is None:
            return None
        if not isinstance(value, list):
            raise self.error(name, f"expected an array of strings, got {type_name(value)}")
        for item in value:
            if not isinstance(item, str):
                raise self.error(
                    name, f"expected an array of strings, got {type_name(item)} {item!r} in it"
                )
        return tuple(value)

    def tables(self, name: str, header: str) -> list[object]:
        """An array of tables (``[[header]]``); empty when absent."""
        value = self.data.get(name, [])
        if not isinstance(value, list):
            raise self.error(
                name, f"expected an array of tables ([[{header}]]), got {type_name(value)}"
            )
        return value

    def required_endpoint(self, name: str) -> Endpoint:
        """A listening address (``"HOST:PORT"``, :func:`~._model.parse_endpoint`)."""
        text = self.required_string(name)
        try:
            return parse_endpoint(text)
        except LocalProtocolError as exc:
            raise self.error(name, str(exc)) from None
