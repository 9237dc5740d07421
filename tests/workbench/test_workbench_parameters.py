"""The parameter list, the line view and the audit page, in Debian's chromium.

A gateway on one simulated SJ300 line of four drives (over TCP), with a
user who may write F002 on drives 1 and 2. What the issue asks: a changed
parameter is highlighted against a backup. Also: the whole set reads with
visible progress, the download is a backup ``sj300 params`` reads, the
factory defaults compare, a malformed upload is a clear error on the page,
a granted edit is confirmed, written, read back and audited, and the line
view shows the frames.

With ``SJ300_SCREENSHOTS=1`` the tests also save the guide's screenshots of
the parameters, the line and the audit page (docs/guide/images/).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import textwrap
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Final

from playwright.async_api import Dialog, Page, expect

from sj300_async.gateway import Gateway, parse_config
from sj300_async.gateway.http import hash_password
from sj300_async.gateway.http._northbound import HttpNorthbound
from sj300_async.profiles import ParameterBackup, get_profile
from sj300_async.simulator import LinePacing, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus
from workbench.browser import BrowserPage

PASSWORD: Final = "a long password"
IMAGES: Final = Path(__file__).resolve().parents[2] / "docs" / "guide" / "images"
ROWS: Final = '[data-testid="parameter-table"] tbody tr'
#: Playwright's wait for the whole set: 335 reads at the simulator's 115200-baud pace are
#: about a second; on a loaded 2-core machine several times that.
READ_TIMEOUT_MS: Final = 60_000


class Plant:
    def __init__(self, gateway: Gateway, sim: SimulatedBus) -> None:
        self.gateway = gateway
        self.sim = sim
        northbound = gateway.northbounds["http"]
        assert isinstance(northbound, HttpNorthbound)
        self.url = f"http://127.0.0.1:{northbound.port}/"


@contextlib.asynccontextmanager
async def plant() -> AsyncIterator[Plant]:
    sim = SimulatedBus(range(1, 5))
    # 115200 baud, the URL's and the simulator's pace alike: a whole set in about a second.
    async with await serve_tcp(sim, pacing=LinePacing(115200, 8, "N", 1)) as server:
        text = textwrap.dedent(
            f"""
            [http]
            listen = "127.0.0.1:0"
            [[http.users]]
            name = "alice"
            password_hash = "{hash_password(PASSWORD)}"
            [[lines]]
            name = "hall"
            url = "tcp://127.0.0.1:{server.port}?baudrate=115200"
            nodes = "1-4"
            interval_s = 0.2
            parameters = ["F002"]
            [[lines.writes]]
            nodes = "1-2"
            parameters = ["F002"]
            """
        )
        async with Gateway(parse_config(text, "workbench.toml")) as gateway:
            yield Plant(gateway, sim)


async def screenshot(page: Page, name: str) -> None:
    if os.environ.get("SJ300_SCREENSHOTS") == "1":
        IMAGES.mkdir(parents=True, exist_ok=True)
        await page.screenshot(path=IMAGES / name, full_page=True)


async def read_all(page: Page) -> None:
    await page.click('[data-testid="read-parameters"]')
    await expect(page.locator('[data-testid="parameters-progress"]')).to_be_visible()
    await expect(page.locator(ROWS)).to_have_count(335, timeout=READ_TIMEOUT_MS)
    await expect(page.locator('[data-testid="parameters-progress"]')).to_be_hidden()


async def test_a_changed_parameter_is_highlighted_against_a_backup(
    page: BrowserPage, tmp_path: Path
) -> None:
    async with plant() as bench:
        web = page.page
        await web.goto(bench.url + "#/drive/hall/1")
        await read_all(web)
        # The download is a backup file that sj300 params reads.
        async with web.expect_download() as waiting:
            await web.click('[data-testid="download-backup"]')
        download = await waiting.value
        saved = tmp_path / download.suggested_filename
        await download.save_as(saved)
        assert saved.name == "hall-1-params.json"
        backup = ParameterBackup.load(saved, get_profile("sj300"))
        assert backup.parameters["F002"] == bench.sim.drives[1].parameters["F002"] == 3000
        # A backup where two parameters differ from the drive.
        data = json.loads(saved.read_text())
        for entry in data["parameters"]:
            if entry["code"] == "F002":
                entry["raw"], entry["value"] = 2500, 25.0
            if entry["code"] == "A004":
                entry["raw"], entry["value"] = 600, 60.0
        changed = tmp_path / "changed.json"
        changed.write_text(json.dumps(data))
        await web.set_input_files('[data-testid="compare-file"]', str(changed))
        highlighted = web.locator(f"{ROWS}.changed")
        await expect(highlighted).to_have_count(2)
        assert await highlighted.evaluate_all("rows => rows.map(r => r.dataset.code)") == [
            "F002",  # the catalogue's order
            "A004",
        ]
        await expect(web.locator(f'{ROWS}[data-code="F002"] [data-field="backup"]')).to_have_text(
            "25"
        )
        await expect(web.locator('[data-testid="parameters-info"]')).to_have_text(
            "2 differences with the file"
        )
        await web.check('[data-testid="only-differences"]')
        await expect(web.locator(ROWS)).to_have_count(2)
        await screenshot(web, "workbench-parameters.png")
        # Against the factory defaults: the simulator sets the command sources to the line.
        await web.uncheck('[data-testid="only-differences"]')
        await web.click('[data-testid="compare-defaults"]')
        await expect(web.locator('[data-testid="parameters-info"]')).to_have_text(
            "2 differences with the factory defaults the catalogue knows"
        )
        defaults = await highlighted.evaluate_all("rows => rows.map(r => r.dataset.code)")
        assert defaults == ["A001", "A002"]
        # Reading is open to anyone: no login on this page, and no edit offered.
        await expect(web.locator('[data-testid="edit"]')).to_have_count(0)
        page.assert_no_errors()


async def test_a_malformed_upload_is_a_clear_error_on_the_page(
    page: BrowserPage, tmp_path: Path
) -> None:
    async with plant() as bench:
        web = page.page
        await web.goto(bench.url + "#/drive/hall/2")
        await read_all(web)
        broken = tmp_path / "broken.json"
        broken.write_text('{"format": "sj300-params", "version": 2, "protocol": "fr700"')
        await web.set_input_files('[data-testid="compare-file"]', str(broken))
        await expect(web.locator('[data-testid="parameters-error"]')).to_contain_text(
            "broken.json: the file: not JSON"
        )
        other = tmp_path / "other.json"
        other.write_text(json.dumps({"format": "sj300-params", "version": 2, "protocol": "fr700"}))
        await web.set_input_files('[data-testid="compare-file"]', str(other))
        await expect(web.locator('[data-testid="parameters-error"]')).to_contain_text(
            "a backup of fr700 drives"
        )
        await expect(web.locator(f"{ROWS}.changed")).to_have_count(0)
        # The page's console may show the 400 of each refused upload: those are the
        # answers asked for, not the page's errors.
        assert all("400" in error for error in page.errors), page.errors


async def test_a_granted_edit_is_confirmed_written_and_audited(page: BrowserPage) -> None:
    async with plant() as bench:
        web = page.page
        await web.goto(bench.url + "#/login")
        await web.fill("input[name=name]", "alice")
        await web.fill("input[name=password]", PASSWORD)
        await web.click("form button")
        await expect(web.locator('[data-testid="user"]')).to_contain_text("alice")
        await web.goto(bench.url + "#/drive/hall/1")
        await read_all(web)
        edits = web.locator('[data-testid="edit"]')
        await expect(edits).to_have_count(1)  # F002 only: the one granted code
        questions: list[str] = []

        async def answer(dialog: Dialog) -> None:
            questions.append(dialog.message)
            await dialog.accept("25" if dialog.type == "prompt" else None)

        web.on("dialog", lambda dialog: asyncio.ensure_future(answer(dialog)))
        await edits.click()
        await expect(web.locator(f'{ROWS}[data-code="F002"] [data-field="raw"]')).to_have_text(
            "2500", timeout=READ_TIMEOUT_MS
        )
        assert bench.sim.drives[1].parameters["F002"] == 2500
        assert len(questions) == 2
        assert questions[0].startswith("F002 acceleration time 1: new value in s")
        assert "F002 acceleration time 1: 30 s → 25 s" in questions[1]  # the diff, to confirm
        record = bench.gateway.audit.recent[-1]
        assert (record["what"], record["old"], record["new"], record["result"]) == (
            "parameter F002",
            30.0,
            25.0,
            "ok",
        )
        assert str(record["client"]).startswith("http:alice#")
        # The audit page shows it.
        await web.goto(bench.url + "#/audit")
        audit_row = web.locator('[data-testid="audit"] tbody tr').first
        await expect(audit_row.locator('[data-field="what"]')).to_have_text("parameter F002")
        await expect(audit_row.locator('[data-field="result"]')).to_have_text("ok")
        await screenshot(web, "workbench-audit.png")
        page.assert_no_errors()


async def test_the_line_view_shows_the_frames_paired(page: BrowserPage) -> None:
    async with plant() as bench:
        web = page.page
        await web.goto(bench.url)
        await web.click('[data-testid="lines"] tbody tr a')
        frames = web.locator('[data-testid="frames"] tbody tr')
        await expect(frames.first).to_be_visible()
        answered = web.locator('[data-testid="frames"] tbody tr td[data-field="answers"]:text("#")')
        await expect(answered.first).to_be_visible()
        await web.select_option('[data-testid="node-filter"]', "3")
        await expect(
            web.locator('[data-testid="frames"] td[data-field="node"]').first
        ).to_have_text("3")
        nodes = await web.locator('[data-testid="frames"] td[data-field="node"]').all_inner_texts()
        assert set(nodes) == {"3"}
        await web.click('[data-testid="paused"]')
        await screenshot(web, "workbench-line.png")
        async with web.expect_download() as waiting:
            await web.click('[data-testid="pcapng"]')
        download = await waiting.value
        assert download.suggested_filename.startswith("hall-")
        assert download.suggested_filename.endswith(".pcapng")
        page.assert_no_errors()
