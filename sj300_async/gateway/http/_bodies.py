"""Request bodies: read within a size limit, parsed as JSON within a depth and a count limit.

Every route of the HTTP northbound that takes a body (the writes, the
login, a backup file's check) reads it with :func:`read_body` and, when it
is JSON, parses it with :func:`parse_json`: one bounded reader, one
bounded parser, so no route can be the one that was forgotten.

Decisions:

- **The depth is checked before anything parses.** The standard
  library's parser recurses once per ``[`` or ``{``: a kilobyte of ``[``
  (issue 41) raised RecursionError, a 500 and a 21-line traceback per
  request. :func:`shape_problem` works on the bytes in C-speed steps
  only, no Python-level loop per byte: it drops escaped backslashes and
  quotes (a JSON backslash escapes exactly the next character, so pairing
  them from the left is the parser's own reading), keeps only quotes and
  brackets (``bytes.translate``), drops the strings (empty ones with
  ``replace``, those holding brackets by splitting at the quotes), then
  refuses a run of more than :data:`MAX_DEPTH` opening brackets, then
  more than :data:`MAX_CONTAINERS` of them in all, and removes the
  innermost pairs, ``replace(b"()", b"")``, at most
  :data:`MAX_DEPTH` times: a pair left after that many passes is nested
  deeper. Exact for JSON; on malformed input it may call a body deep that
  is also broken, and what it lets through is at most twice
  :data:`MAX_DEPTH` deep, far below the parser's recursion limit, which
  then says what is wrong with it. RecursionError is caught all the same,
  as a last guard.
- **So is the number of arrays and objects**, before the passes: a
  megabyte of small nested lists, none deeper than 16, took the parser
  800 ms (each a container the collector tracks), and the passes 55 ms
  (each removes one level of every list). A request body (a login, a
  write) is one object: :data:`MAX_CONTAINERS` is 64; a backup file is
  one per parameter (1,002 for a whole FR-700 set), and its check allows
  4,096. :data:`MAX_DEPTH` is 32 (the deepest body the gateway reads is 3
  levels). Measured on a 2-core machine, the check of the worst megabyte
  (strings full of brackets and escapes) costs 25 ms of the loop, of
  64 KiB (a write's) 2 ms; what it lets through, a megabyte of numbers or
  keys, costs the parser 50-130 ms, and the backup check has a budget per
  address (:mod:`._guards`).
- **UTF-8 only**, as RFC 8259 asks of JSON between systems: the check
  reads bytes, and in UTF-8 a byte below 0x80 is always that character.
- A body's size is checked against ``Content-Length`` before reading, then
  while reading (a chunked body has none); its time is the server's
  (``body_timeout_s``, :mod:`._server`).
"""

from __future__ import annotations

import json
from typing import Any, Final

from aiohttp import web

from .. import excerpt
from ._replies import json_error

__all__ = [
    "MAX_CONTAINERS",
    "MAX_DEPTH",
    "BadJson",
    "parse_json",
    "read_body",
    "read_json_object",
    "shape_problem",
]

#: The deepest nesting of arrays and objects a JSON body may have (the module docstring).
MAX_DEPTH: Final = 32
#: The arrays and objects a request's JSON body may have in all.
MAX_CONTAINERS: Final = 64

#: Every byte but quotes and brackets (deleted), and the brackets as one pair of kinds.
_NOT_SKELETON: Final = bytes(sorted(set(range(256)) - set(b'"[]{}')))
_AS_PARENS: Final = bytes.maketrans(b"[{]}", b"(())")
#: Bytes read at a time.
_CHUNK: Final = 64 * 1024


class BadJson(ValueError):
    """A body that is not JSON the gateway reads; its message is the reason, for a 400."""


def _skeleton(data: bytes) -> bytes:
    """*data*'s brackets outside strings, as ``(`` and ``)`` (the module docstring)."""
    text = data.replace(b"\\\\", b"").replace(b'\\"', b"")
    skeleton = text.translate(_AS_PARENS, _NOT_SKELETON).replace(b'""', b"")
    if b'"' in skeleton:  # strings with brackets in them: every other piece is outside
        skeleton = b"".join(skeleton.split(b'"')[::2])
    return skeleton


def shape_problem(
    data: bytes, max_depth: int = MAX_DEPTH, max_containers: int = MAX_CONTAINERS
) -> str | None:
    """Why *data* is nested too deeply, or holds too many arrays and objects, to parse;
    None when it does not (see the module docstring)."""
    skeleton = _skeleton(data)
    too_deep = f"nested deeper than {max_depth} levels"
    if b"(" * (max_depth + 1) in skeleton:  # opened one after the other: all open at once
        return too_deep
    if skeleton.count(b"(") > max_containers:  # before the passes, which it bounds
        return f"more than {max_containers} arrays and objects"
    for _ in range(max_depth):
        if not skeleton:
            return None
        shorter = skeleton.replace(b"()", b"")
        if len(shorter) == len(skeleton):
            break  # no pair left, only brackets without a partner
        skeleton = shorter
    opening = skeleton.find(b"(")
    if opening < 0:
        return None
    # A pair still there is deeper than max_depth; with no ")" at all, every "(" left
    # is open at the end of the body, all at once.
    closing = skeleton.rfind(b")")
    if closing > opening or (closing < 0 and len(skeleton) > max_depth):
        return too_deep
    return None


def parse_json(
    data: bytes, max_depth: int = MAX_DEPTH, max_containers: int = MAX_CONTAINERS
) -> Any:
    """*data* (UTF-8 JSON) parsed, no deeper than *max_depth*, with at most
    *max_containers* arrays and objects.

    Raises:
        BadJson: not UTF-8, nested too deeply, too many arrays and objects, or not JSON
            (the message says which).
    """
    problem = shape_problem(data, max_depth, max_containers)
    if problem is not None:
        raise BadJson(f"not JSON the gateway reads: {problem}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise BadJson("not JSON: not UTF-8") from None
    try:
        return json.loads(text.removeprefix("\ufeff"))
    except RecursionError:  # the check above makes it impossible: a last guard
        raise BadJson("not JSON the gateway reads: nested too deeply") from None
    except ValueError as exc:
        raise BadJson(f"not JSON ({exc}): {excerpt(data)}") from None


async def read_body(request: web.Request, max_bytes: int, what: str = "the body") -> bytes:
    """The request's whole body, at most *max_bytes*.

    Raises:
        HTTPException: 413, *what* over *max_bytes* (said before reading when
            ``Content-Length`` says so).
    """
    limit = f"{what} is at most {_size(max_bytes)}"
    if request.content_length is not None and request.content_length > max_bytes:
        raise json_error(413, limit)
    body = bytearray()
    # read(n) gives what has arrived so far, not n bytes: read to the end, or past the
    # limit (a body without Content-Length, chunked, is only measured as it comes).
    while chunk := await request.content.read(_CHUNK):
        body += chunk
        if len(body) > max_bytes:
            raise json_error(413, limit)
    return bytes(body)


async def read_json_object(request: web.Request, max_bytes: int) -> dict[str, Any]:
    """The request's body as a JSON object (an empty body is ``{}``).

    Raises:
        HTTPException: 415 not ``application/json``, 413 too large, 400 not a JSON
            object (not UTF-8, its shape past :func:`shape_problem`'s limits, malformed,
            or another type).
    """
    if not request.body_exists:
        return {}
    if request.content_type != "application/json":
        raise json_error(415, f"expected application/json, got {excerpt(request.content_type)}")
    data = await read_body(request, max_bytes)
    try:
        body = parse_json(data)
    except BadJson as exc:
        raise json_error(400, str(exc)) from None
    if not isinstance(body, dict):
        raise json_error(400, f"expected a JSON object, got {excerpt(data)}")
    return body


def _size(n: int) -> str:
    return f"{n // 1024} KiB" if n % 1024 == 0 else f"{n} bytes"
