"""tshark with the project's Wireshark dissector (contrib/wireshark/sj300_async.lua).

Shared by the dissector's tests and by those of the files the gateway writes
(a trip record's frames): a capture decoded by Debian's ``tshark -2`` in an
empty HOME, every packet's fields, and no Lua error anywhere.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Sequence
from pathlib import Path

DISSECTOR = Path(__file__).resolve().parents[1] / "contrib" / "wireshark" / "sj300_async.lua"

SJ300_FIELDS = (
    "sj300.type",
    "sj300.node",
    "sj300.command",
    "sj300.kind",
    "sj300.nak_code",
    "sj300.bcc_ok",
    "sj300.request_in",
    "sj300.response_in",
)
FR700_FIELDS = (
    "fr700.type",
    "fr700.format",
    "fr700.station",
    "fr700.instruction",
    "fr700.wait",
    "fr700.nak_code",
    "fr700.sum_ok",
    "fr700.request_in",
    "fr700.response_in",
    "fr700.reply_in",
    "fr700.terminator",
)

Row = dict[str, str]


def _tshark() -> str:
    path = shutil.which("tshark")
    if path is None:
        raise RuntimeError("tshark is not installed (make system-packages installs it)")
    return path


def decode(capture: Path, fields: Sequence[str], home: Path) -> list[Row]:
    """Every packet's *fields* (and its expert messages) as tshark -2 decodes them."""
    home.mkdir(exist_ok=True)
    every = ("frame.number", *fields, "_ws.expert.message")
    result = subprocess.run(
        [_tshark(), "-2", "-n", "-X", f"lua_script:{DISSECTOR}", "-r", str(capture),
         "-T", "fields", "-E", "separator=/t", "-E", "aggregator=;", "-E", "quote=n",
         *(arg for field in every for arg in ("-e", field))],
        env={**os.environ, "HOME": str(home), "XDG_CONFIG_HOME": str(home / ".config")},
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "Lua" not in result.stderr, result.stderr
    rows = [dict(zip(every, line.split("\t"), strict=True)) for line in result.stdout.splitlines()]
    assert [row["frame.number"] for row in rows] == [str(n) for n in range(1, len(rows) + 1)]
    for row in rows:
        assert "Lua Error" not in row["_ws.expert.message"], row
    return rows


def table(rows: list[Row], fields: Sequence[str]) -> list[tuple[str, ...]]:
    return [tuple(row[field] for field in fields) for row in rows]
