"""A record's CSV made in a child process, never in the gateway's.

Decisions:

- **A child, not a thread.** orjson parses a record holding the GIL: a
  record of a million samples (28 MB) held it 0.44 s, and a thread's CSV
  of it took 3.8 s of the loop's interpreter besides. A fast poll with a
  long window makes records that size (the trend keeps a sample a poll).
  In a child, the parse and the CSV cost the loop a pipe's reads, and the
  gateway's memory the CSV's bytes, not the record's objects.
- The child is this interpreter running :mod:`._samples_csv` by its path,
  ``-P`` (the script's directory off ``sys.path``: it holds modules named
  as the standard library's ``_csv``). It is killed at :data:`TIMEOUT_S`
  and when the caller is cancelled. How many run at once is the caller's
  bound (the workbench's readers).
- JSON that is no record is :class:`ValueError` (the door says 404); a
  child that could not start, crashed or ran out of time is
  :class:`CsvFailed` (503): the record may be fine, the gateway says why.
"""

from __future__ import annotations

import asyncio
import contextlib
import sys
from pathlib import Path
from typing import Final

from ._samples_csv import NOT_A_RECORD

__all__ = ["TIMEOUT_S", "CsvFailed", "record_csv"]

#: The longest a child may take: a million samples take about 4 s.
TIMEOUT_S: Final = 300.0
#: The child: this interpreter, the script by its path.
CHILD: Final = (sys.executable, "-P", str(Path(__file__).with_name("_samples_csv.py")))
#: The most characters of a child's stderr a failure says.
_EXCERPT: Final = 200


class CsvFailed(Exception):
    """The child could not make a record's CSV (see the module docstring)."""


async def record_csv(
    data: bytes, *, timeout_s: float = TIMEOUT_S, child: tuple[str, ...] | None = None
) -> bytes:
    """The CSV of the record whose JSON is *data*, made by *child* (:data:`CHILD`).

    Raises:
        ValueError: *data* is no record (the child's reason).
        CsvFailed: the child did not start, failed, or ran past *timeout_s*.
    """
    try:
        process = await asyncio.create_subprocess_exec(
            *(child or CHILD),
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
        )
    except OSError as exc:
        raise CsvFailed(f"the CSV's process did not start: {exc}") from None
    try:
        async with asyncio.timeout(timeout_s):
            out, err = await process.communicate(data)
    except TimeoutError:
        raise CsvFailed(f"the CSV took more than {timeout_s:g} s") from None
    finally:
        if process.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                process.kill()
            await process.wait()
    reason = " ".join(err.decode(errors="replace").split())[:_EXCERPT]
    if process.returncode == NOT_A_RECORD:
        raise ValueError(reason)
    if process.returncode != 0:
        raise CsvFailed(f"the CSV's process ended with status {process.returncode}: {reason}")
    return out
