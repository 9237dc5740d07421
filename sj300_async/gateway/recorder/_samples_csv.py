"""A trip record's samples as CSV, and the child process that makes it.

The CSV is the samples, one row each, in the trend download's shape
(``time_utc``, ``time_unix``, then every column), empty for null.

Run as a script (``python -P _samples_csv.py``), this module is the child
:mod:`._csv_process` starts: the record's JSON on stdin, its CSV on stdout,
exit status :data:`NOT_A_RECORD` with one line on stderr when the JSON is
no record. It imports the standard library and orjson only, and nothing of
the package (it is run by its path, not as ``-m``), so that a child costs
tens of milliseconds and the gateway's imports nothing.
"""

from __future__ import annotations

import csv
import io
import sys
from collections.abc import Mapping
from datetime import UTC, datetime
from typing import Any, Final

__all__ = ["NOT_A_RECORD", "samples_csv", "utc_text"]

#: The child's exit status for JSON that is no record (its reason on stderr).
NOT_A_RECORD: Final = 3
#: The most characters of a reason the child says.
_REASON_CHARS: Final = 200


def utc_text(unix: float) -> str:
    return datetime.fromtimestamp(unix, UTC).isoformat(timespec="milliseconds")


def samples_csv(record: Mapping[str, Any]) -> str:
    """A record's samples as CSV (see the module docstring).

    Raises:
        ValueError: the record has no samples of the shape it should.
        OverflowError: a sample's time is no date.
    """
    samples = record.get("samples")
    if not isinstance(samples, dict) or not isinstance(samples.get("time"), list):
        raise ValueError("the record has no samples")
    names = [name for name in samples if name != "time"]
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\r\n")
    writer.writerow(["time_utc", "time_unix", *names])
    for row, at in enumerate(samples["time"]):
        if not isinstance(at, int | float):
            raise ValueError(f"sample {row}: its time is not a number")
        values = []
        for name in names:
            column = samples[name]
            value = column[row] if isinstance(column, list) and row < len(column) else None
            values.append("" if value is None else value)
        writer.writerow([utc_text(at), f"{at:.3f}", *values])
    return out.getvalue()


def _main() -> int:
    import orjson

    try:
        record = orjson.loads(sys.stdin.buffer.read())
        if not isinstance(record, dict):
            raise ValueError("not a JSON object")
        text = samples_csv(record)
    except (ValueError, OverflowError, OSError) as exc:  # orjson's error is a ValueError
        sys.stderr.write(" ".join(str(exc).split())[:_REASON_CHARS] + "\n")
        return NOT_A_RECORD
    sys.stdout.buffer.write(text.encode())
    return 0


if __name__ == "__main__":
    sys.exit(_main())
