"""contrib/grafana's dashboard and contrib/prometheus's alerting rules, against a gateway.

Every metric they query is one a running gateway with every northbound exports (its
``/metrics``, as Prometheus scrapes it); Debian's Prometheus, scraping that gateway every
second, answers every panel's query with data; ``promtool`` checks the rules and runs
their unit tests; and one rule (a line down) is seen firing on the real gateway.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import shutil
import socket
import subprocess
import textwrap
import urllib.parse
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest
from cli.clirun import TIMEOUT, closed_port
from mqtt_broker import running_broker

from sj300_async.gateway import Gateway, parse_config

ROOT = Path(__file__).resolve().parents[2]
DASHBOARD = ROOT / "contrib" / "grafana" / "sj300-gateway.json"
RULES = ROOT / "contrib" / "prometheus" / "sj300-alerts.yml"
RULE_TESTS = ROOT / "contrib" / "prometheus" / "sj300-alerts.test.yml"
_METRIC = re.compile(r"\bsj300_[a-z0-9_]+")
#: The dashboard's variables as a query of all of it (Grafana's own, with a 1 s scrape).
_VARIABLES = {
    "$instance": ".*",
    "$line": ".*",
    "$__rate_interval": "5s",
    "$__range": "1m",
}

needs_prometheus = pytest.mark.skipif(
    shutil.which("prometheus") is None or shutil.which("promtool") is None,
    reason="Debian's prometheus package is not installed",
)


def _dashboard() -> dict[str, Any]:
    loaded: dict[str, Any] = json.loads(DASHBOARD.read_text())
    return loaded


def _panels() -> list[dict[str, Any]]:
    return [panel for panel in _dashboard()["panels"] if panel["type"] != "row"]


def _queries() -> list[str]:
    return [target["expr"] for panel in _panels() for target in panel["targets"]]


def _rule_exprs() -> list[str]:
    return re.findall(r"^\s+expr: (.+)$", RULES.read_text(), re.MULTILINE)


def _concrete(expr: str) -> str:
    for variable, value in _VARIABLES.items():
        expr = expr.replace(variable, value)
    assert "$" not in expr, expr
    return expr


def _exported(text: str) -> set[str]:
    """Every sample name /metrics *text* declares (a histogram's series too)."""
    names = set()
    for name, kind in re.findall(r"^# TYPE (\S+) (\S+)$", text, re.MULTILINE):
        names.add(name)
        if kind == "histogram":
            names |= {f"{name}_bucket", f"{name}_sum", f"{name}_count"}
    return names


def _config(broker: int, down_port: int) -> str:
    """Every northbound, a line polled and a line down (its device server is not there)."""
    return textwrap.dedent(
        f"""
        [gateway]
        id = "gw1"
        [modbus]
        listen = "127.0.0.1:0"
        [http]
        listen = "127.0.0.1:0"
        [mqtt]
        url = "mqtt://127.0.0.1:{broker}"
        [sparkplug]
        url = "mqtt://127.0.0.1:{broker}"
        group_id = "plant"
        [opcua]
        endpoint = "opc.tcp://127.0.0.1:0"
        security = ["None"]
        nodeset_cache = ""
        [[lines]]
        name = "hall"
        url = "sim://?nodes=1-2"
        nodes = "1-2"
        interval_s = 0.2
        [[lines.writes]]
        nodes = "1"
        control = true
        [[lines]]
        name = "yard"
        url = "tcp://127.0.0.1:{down_port}"
        nodes = "1"
        unit_offset = 10
        """
    )


@contextlib.asynccontextmanager
async def _gateway(tmp_path: Path) -> AsyncIterator[tuple[Gateway, int]]:
    (tmp_path / "broker").mkdir()
    async with running_broker(tmp_path / "broker") as broker:
        text = _config(broker.port, closed_port())
        async with Gateway(parse_config(text, str(tmp_path / "gw.toml"))) as gateway:
            yield gateway, gateway.northbounds["http"].port  # type: ignore[attr-defined]


# -- the files alone -----------------------------------------------------------------------


def test_the_dashboard_is_well_formed() -> None:
    dashboard = _dashboard()
    assert dashboard["uid"] == "sj300-gateway"
    ids = [panel["id"] for panel in dashboard["panels"]]
    assert len(ids) == len(set(ids))
    for panel in _panels():
        grid = panel["gridPos"]
        assert grid["x"] + grid["w"] <= 24, panel["title"]
        assert panel["datasource"] == {"type": "prometheus", "uid": "${datasource}"}
        assert panel["targets"], panel["title"]
        refs = [target["refId"] for target in panel["targets"]]
        assert len(refs) == len(set(refs)), panel["title"]
    titles = " ".join(panel["title"] for panel in _panels()).lower()
    for subject in ("utilisation", "latency", "time-outs", "bad frames", "online", "stale",
                    "lapse", "clients", "mqtt", "opc ua", "loop lag"):  # fmt: skip
        assert subject in titles, subject


@needs_prometheus
def test_promtool_checks_the_rules_and_runs_their_tests() -> None:
    checked = subprocess.run(
        ["promtool", "check", "rules", str(RULES)], capture_output=True, text=True, check=False
    )
    assert checked.returncode == 0, checked.stdout + checked.stderr
    assert "SUCCESS: 5 rules found" in checked.stdout
    tested = subprocess.run(
        ["promtool", "test", "rules", RULE_TESTS.name],
        capture_output=True,
        text=True,
        check=False,
        cwd=RULE_TESTS.parent,
    )
    assert tested.returncode == 0, tested.stdout + tested.stderr


# -- against a gateway ---------------------------------------------------------------------


async def test_every_metric_queried_is_one_the_gateway_exports(tmp_path: Path) -> None:
    async with (
        _gateway(tmp_path) as (_, port),
        aiohttp.ClientSession() as session,
        session.get(f"http://127.0.0.1:{port}/metrics") as response,
    ):
        exported = _exported(await response.text())
    queried = {name for expr in _queries() + _rule_exprs() for name in _METRIC.findall(expr)}
    assert len(queried) > 40
    assert queried - exported == set()


@contextlib.contextmanager
def _prometheus(directory: Path, target: int) -> Iterator[str]:
    """Debian's Prometheus scraping 127.0.0.1:*target* four times a second (its six
    scrapes took 6 s at its usual 1 s), the rules evaluated as often and loaded with
    their ``for`` cut to 0 s (the expressions are the file's); its API's URL."""
    directory.mkdir()
    rules = directory / "rules.yml"
    rules.write_text(re.sub(r"for: \S+", "for: 0s", RULES.read_text()))
    config = directory / "prometheus.yml"
    config.write_text(
        textwrap.dedent(
            f"""
            global:
              scrape_interval: 250ms
              evaluation_interval: 250ms
            rule_files: ["{rules}"]
            scrape_configs:
              - job_name: sj300
                static_configs:
                  - targets: ["127.0.0.1:{target}"]
            """
        )
    )
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    process = subprocess.Popen(
        [
            "prometheus",
            f"--config.file={config}",
            f"--storage.tsdb.path={directory / 'data'}",
            f"--web.listen-address=127.0.0.1:{port}",
            "--log.level=warn",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        yield f"http://127.0.0.1:{port}/api/v1"
    finally:
        process.terminate()
        try:
            process.wait(10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


async def _query(session: aiohttp.ClientSession, api: str, expr: str) -> list[Any]:
    url = f"{api}/query?query={urllib.parse.quote(expr)}"
    async with session.get(url) as response:
        body = await response.json()
    assert body["status"] == "success", (expr, body)
    result: list[Any] = body["data"]["result"]
    return result


async def _until(what: str, check: Any) -> None:
    """Return once the coroutine function *check* returns true (Prometheus's own pace)."""
    async with asyncio.timeout(TIMEOUT):
        while True:
            with contextlib.suppress(aiohttp.ClientError):
                if await check():
                    return
            await asyncio.sleep(0.2)


@needs_prometheus
@pytest.mark.timeout(90)
async def test_prometheus_answers_every_panel_and_a_rule_fires(tmp_path: Path) -> None:
    async with _gateway(tmp_path) as (_, port), aiohttp.ClientSession() as session:
        with _prometheus(tmp_path / "prometheus", port) as api:

            async def scraped_enough() -> bool:
                found = await _query(session, api, "count_over_time(sj300_line_up[1m])")
                return bool(found) and min(int(r["value"][1]) for r in found) >= 6

            await _until("six scrapes", scraped_enough)
            empty = []
            for expr in _queries():
                if not await _query(session, api, _concrete(expr)):
                    empty.append(expr)
            assert empty == []

            async def line_down_fires() -> bool:
                async with session.get(f"{api}/alerts") as response:
                    alerts = (await response.json())["data"]["alerts"]
                return any(
                    a["labels"]["alertname"] == "SJ300LineDown"
                    and a["labels"]["line"] == "yard"
                    and a["state"] == "firing"
                    for a in alerts
                )

            await _until("SJ300LineDown firing", line_down_fires)
