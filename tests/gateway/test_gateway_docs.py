"""docs/GATEWAY.md's register tables say what the code serves (they cannot drift apart)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from sj300_async.gateway.modbus import describe
from sj300_async.profiles import get_profile

DOC = (Path(__file__).parents[2] / "docs" / "GATEWAY.md").read_text(encoding="utf-8")
#: The typography of the document: an en dash in a register range, a multiplication sign.
DASH, TIMES = "\u2013", "\u00d7"
_ROW = re.compile(rf"^\| ([0-9]+(?:{DASH}[0-9]+)?) \| [^|]+ \| ([^|]+) \| (R/W|R) \|$", re.M)
SECTIONS = {"sj300": "### SJ300 only", "fr700": "### FR-700 only"}


def _rows(heading: str) -> dict[str, tuple[str, str]]:
    """The register rows of the table under *heading*."""
    section = DOC.split(heading, 1)[1].split("\n### ", 1)[0]
    return {m.group(1): (m.group(2).strip(), m.group(3)) for m in _ROW.finditer(section)}


@pytest.mark.parametrize("protocol", ["sj300", "fr700"])
def test_every_fixed_register_is_documented_with_its_step(protocol: str) -> None:
    rows = _rows("### Both protocols") | _rows(SECTIONS[protocol])
    served = set()
    for address, width, _name, step, writable in describe(get_profile(protocol)):
        if 302 <= address < 362:
            continue  # the six trip records: documented as one pattern
        key = str(address) if width == 1 else f"{address}{DASH}{address + width - 1}"
        served.add(key)
        assert key in rows, f"register {key} of {protocol} is not in docs/GATEWAY.md"
        assert rows[key] == (step, "R/W" if writable else "R"), key
    assert set(rows) == served, "docs/GATEWAY.md lists registers the gateway does not serve"


@pytest.mark.parametrize("protocol", ["sj300", "fr700"])
def test_every_parameter_base_is_documented(protocol: str) -> None:
    for base in get_profile(protocol).registers.parameter_bases.values():
        assert f"| {base} + 2 {TIMES} number" in DOC
