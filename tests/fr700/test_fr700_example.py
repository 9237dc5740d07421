"""The FR-700 example runs against the in-memory simulator, as CI runs it."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "fr700_one_shot.py"


def test_fr700_one_shot() -> None:
    done = subprocess.run(
        [sys.executable, str(EXAMPLE)], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 0, done.stderr
    assert re.search(r"station 0: running, \d+\.\d\d Hz", done.stdout)
    assert (
        "refused by the drive (data range): station 00 answered NAK C (data range error)"
        in done.stdout
    )
