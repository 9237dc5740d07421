"""docs/GATEWAY.md says what the code does: its register tables, the configuration file's
keys, the metrics table (they cannot drift apart)."""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import pytest

from sj300_async.gateway import Gateway, get_northbound, northbound_names, parse_config
from sj300_async.gateway._config import _GATEWAY_KEYS
from sj300_async.gateway._config_lines import _GRANT_KEYS, _LINE_KEYS
from sj300_async.gateway.modbus import describe
from sj300_async.profiles import get_profile

from .conftest import polled

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


def _toml_example() -> str:
    """The configuration file's example: the first TOML block."""
    return DOC.split("```toml\n", 1)[1].split("```", 1)[0]


def test_every_key_of_the_configuration_file_is_in_its_example() -> None:
    example = _toml_example()
    sections = {"gateway": _GATEWAY_KEYS, "lines": _LINE_KEYS, "lines.writes": _GRANT_KEYS}
    sections |= {name: tuple(get_northbound(name).keys) for name in northbound_names()}
    for section, keys in sections.items():
        for key in keys:
            if key == "writes":
                assert "[[lines.writes]]" in example
                continue
            arrays = (
                ("http", "users"), ("http", "tokens"), ("opcua", "users"), ("modbus", "listeners"),
            )  # fmt: skip
            if (section, key) in arrays:  # arrays of tables
                table = f"[[{section}.{key}]]"
                assert re.search(rf"^ *(# )?{re.escape(table)}", example, re.M), table
                continue
            written = re.search(rf"^ *(# )?{key} = ", example, re.M)
            assert written, f"[{section}] {key} is not in docs/GATEWAY.md's configuration file"


def _documented_metrics() -> set[str]:
    """The metrics table's names, ``_replies_total`` after ``sj300_line_requests_total``
    read as ``sj300_line_replies_total``."""
    table = DOC.split("| metric | labels | what |", 1)[1].split("\n\n", 1)[0]
    names = set()
    for row in table.splitlines()[2:]:
        cell = row.split(" | ", 1)[0]
        words = re.findall(r"`([a-z0-9_]+)`", cell)
        prefix = "_".join(words[0].split("_")[:2])
        names |= {prefix + w if w.startswith("_") else w for w in words}
    return names


async def test_every_metric_the_gateway_exports_is_in_the_metrics_table(tmp_path: Path) -> None:
    """Every family of a gateway with each built-in northbound (the broker need not answer)."""
    text = f"""
        [opcua]
        endpoint = "opc.tcp://127.0.0.1:0"
        certificate = "{tmp_path / "cert.der"}"
        private_key = "{tmp_path / "key.pem"}"
        [modbus]
        listen = "127.0.0.1:0"
        [metrics]
        listen = "127.0.0.1:0"
        [mqtt]
        url = "mqtt://127.0.0.1:1"
        [[lines]]
        url = "sim://?nodes=1"
        nodes = "1"
        interval_s = 0.05
        """
    async with Gateway(parse_config(textwrap.dedent(text), "docs.toml")) as gateway:
        await polled(gateway)
        families = list(gateway.metrics())
    suffix = {"counter": "_total", "gauge": "", "histogram": "", "summary": ""}
    exported = {family.name + suffix[family.type] for family in families}
    assert {"sj300_gateway_read_errors_total", "sj300_mqtt_commands_total"} <= exported
    assert "sj300_opcua_writes_total" in exported
    missing = exported - _documented_metrics()
    assert not missing, f"metrics missing from docs/GATEWAY.md's table: {sorted(missing)}"
