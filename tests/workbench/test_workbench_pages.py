"""The workbench's pages in a real browser, on a real gateway polling simulated drives.

Each test starts its own gateway (tests/workbench/gateway.py: simulated
lines over TCP, ``hall`` with eight drives and, for the overview, ``press``
with two, polled every 0.2 s, the workbench on a free loopback port) and
its own chromium (tests/workbench/conftest.py), and stops both.

With ``SJ300_SCREENSHOTS=1`` in the environment, the trip test also saves
the guide's screenshots of the overview and of a drive's page
(docs/guide/images/); without it, it takes none and writes nothing.
"""

from __future__ import annotations

import contextlib
import csv
import io
import os
import statistics
from collections.abc import AsyncIterator, Callable, Mapping
from datetime import datetime, timedelta
from decimal import ROUND_HALF_UP, Decimal
from pathlib import Path
from typing import Any, Final

from playwright.async_api import Locator, Page, expect
from waiting import wait_for

from workbench.browser import BrowserPage
from workbench.gateway import GATEWAY_ID, INTERVAL_S, Bench, Published, workbench_gateway

#: Two lines: the overview shows each, and its drives in the gateway's order.
LINES: Final = {"hall": range(1, 9), "press": range(1, 3)}
#: One line of eight drives (the guide's screenshots: "one line, eight drives").
HALL: Final = {"hall": range(1, 9)}
#: Milliseconds Playwright waits for a state of the page (generous: a loaded 2-core machine).
WAIT_MS: Final = 15_000
#: Seconds the test waits for a state of the gateway.
WAIT_S: Final = 15.0
#: How late the overview may show a change after the gateway published it, beyond one poll
#: interval. The page is pushed each snapshot (server-sent events) and draws it at the next
#: animation frame; the stream gathers its writes for up to 50 ms. Measured on 2 cores: 41 ms
#: at the median, 66 ms at worst (before the gathering: 10 ms, and 110 ms at worst in 25 runs
#: on a machine shared with other jobs at load 4, 25 ms with two test workers and two CPU
#: hogs). 0.8 s is seven times the worst; yet a page that polled every 2 s would be late by 1 s on
#: average, and the test times every one of the first CHANGES values the page shows (none
#: may be late; such a page would not even show CHANGES values within WAIT_MS).
SLACK_S: Final = 0.8
#: Changes of the output frequency the overview test measures, one per poll.
CHANGES: Final = 8
#: The trend's series colours (static/app.js, SERIES): output Hz, current A, voltage V.
SERIES_RGB: Final = ((0x1F, 0x6F, 0xEB), (0xD9, 0x48, 0x0F), (0x2B, 0x8A, 0x3E))
#: Where the guide's screenshots go, when SJ300_SCREENSHOTS=1.
IMAGES: Final = Path(__file__).resolve().parents[2] / "docs" / "guide" / "images"

DRIVES_ROWS: Final = '[data-testid="drives"] tbody tr'
LINES_ROWS: Final = '[data-testid="lines"] tbody tr'
TRIPS_ROWS: Final = '[data-testid="trips"] tbody tr'

#: The trip test's line at work (Hz): seven drives at their speeds, node 8 stopped, node 3
#: about to trip.
SPEEDS: Final = {1: 50.0, 2: 35.0, 3: 40.0, 4: 25.0, 5: 45.0, 6: 30.0, 7: 20.0}


def keys(lines: Mapping[str, range]) -> list[str]:
    """Every drive's key (``LINE/NODE``), in the gateway's order."""
    return [f"{line}/{node}" for line, nodes in lines.items() for node in nodes]


@contextlib.asynccontextmanager
async def online_bench(lines: Mapping[str, range]) -> AsyncIterator[Bench]:
    """A gateway on *lines*, every drive online.

    Entered in the test itself, not in a fixture: the poller's task group must be left by
    the task that entered it, and an async fixture's teardown runs in another.
    """
    async with workbench_gateway(lines) as running:
        await wait_for(
            lambda: all(d.snapshot.available for d in running.gateway.drives),
            "every drive online",
            timeout=WAIT_S,
        )
        yield running


def screenshots() -> bool:
    return os.environ.get("SJ300_SCREENSHOTS") == "1"


async def screenshot(page: Page, name: str) -> None:
    """Save the whole page as the guide's *name* (only with SJ300_SCREENSHOTS=1)."""
    if screenshots():
        IMAGES.mkdir(parents=True, exist_ok=True)
        await page.screenshot(path=IMAGES / name, full_page=True)


def row(page: Page, key: str) -> Locator:
    """The overview's row of drive *key* (``LINE/NODE``)."""
    return page.locator(f'{DRIVES_ROWS}[data-key="{key}"]')


def fixed(value: float, digits: int) -> str:
    """*value* as JavaScript's ``toFixed(digits)`` writes it (a tie rounds away from zero)."""
    return str(Decimal(value).quantize(Decimal(1).scaleb(-digits), rounding=ROUND_HALF_UP))


def first_published(
    published: list[Published], shown: Callable[[Published], bool], what: str
) -> Published:
    found = next((p for p in published if shown(p)), None)
    assert found is not None, f"the page showed {what}, which the gateway never published"
    return found


def showing_hz(text: str) -> Callable[[Published], bool]:
    """Whether a published snapshot's output frequency is *text* as the overview writes it."""

    def shows(published: Published) -> bool:
        hz = published.snapshot.output_frequency_hz
        return hz is not None and fixed(hz, 2) == text

    return shows


# The overview's cells of one drive, each time one changes: [text, Date.now()] per field.
WATCH_ROW: Final = """([key, fields]) => {
    const body = document.querySelector('[data-testid="drives"] tbody');
    const seen = Object.fromEntries(fields.map((field) => [field, []]));
    const read = () => {
        const now = Date.now();
        for (const field of fields) {
            const cell = body.querySelector(`tr[data-key="${key}"] td[data-field="${field}"]`);
            const value = cell === null ? null : cell.textContent;
            const list = seen[field];
            if (!list.length || list[list.length - 1][0] !== value) list.push([value, now]);
        }
    };
    read();
    new MutationObserver(read).observe(body, {childList: true, subtree: true, characterData: true});
    window.seen = seen;
}"""


async def test_the_overview_shows_every_line_and_drive_and_follows_a_start(
    page: BrowserPage, record_property: Callable[[str, object], None]
) -> None:
    async with online_bench(LINES) as bench:
        p = page.page
        await p.goto(bench.url)

        await expect(p.locator(DRIVES_ROWS)).to_have_count(len(keys(LINES)), timeout=WAIT_MS)
        assert [
            await r.get_attribute("data-key") for r in await p.locator(DRIVES_ROWS).all()
        ] == keys(LINES)
        for key in keys(LINES):
            await expect(row(p, key).locator('[data-field="online"]')).to_have_text("online")
            await expect(row(p, key).locator('[data-field="state"]')).to_have_text("stopped")
            await expect(row(p, key).locator('[data-field="output_frequency_hz"]')).to_have_text(
                "0.00"
            )
        await expect(p.locator(LINES_ROWS)).to_have_count(len(LINES))
        for line, name in zip(await p.locator(LINES_ROWS).all(), LINES, strict=True):
            await expect(line.locator('[data-field="name"]')).to_have_text(name)
            await expect(line.locator('[data-field="connected"]')).to_have_text("up")
            count = len(LINES[name])
            await expect(line.locator('[data-field="drives_online"]')).to_have_text(
                f"{count} of {count}"
            )
        await expect(p.get_by_test_id("gateway")).to_contain_text(GATEWAY_ID)
        await expect(p.get_by_test_id("live")).to_have_text("live")

        # Start hall/2 (a 30 s ramp to 50 Hz: its output changes at every poll) and time each
        # change from the gateway's publishing it to the overview's showing it.
        await p.evaluate(WATCH_ROW, ["hall/2", ["state", "output_frequency_hz"]])
        await bench.start("hall", 2, 40.0)
        await p.wait_for_function(
            "n => window.seen.output_frequency_hz.length > n", arg=CHANGES, timeout=WAIT_MS
        )
        seen: Mapping[str, list[tuple[str, float]]] = await p.evaluate("window.seen")
        published = bench.publications("hall", 2)

        delays: list[float] = []
        assert seen["state"][0][0] == "stopped"
        state, at_ms = seen["state"][1]
        assert state == "accelerating"
        first = first_published(published, lambda q: q.snapshot.state == state, repr(state))
        delays.append(at_ms / 1000 - first.at)
        assert seen["output_frequency_hz"][0][0] == "0.00"
        for text, at_ms in seen["output_frequency_hz"][1 : CHANGES + 1]:
            hz = first_published(published, showing_hz(text), f"{text} Hz")
            delays.append(at_ms / 1000 - hz.at)
        record_property("update_delays_s", [round(d, 4) for d in delays])
        record_property("update_delay_median_s", round(statistics.median(delays), 4))
        # the browser and the test read the same clock: a change is never shown before it is sent
        assert min(delays) > -0.002, delays
        assert max(delays) < INTERVAL_S + SLACK_S, delays
        page.assert_no_errors()


async def test_a_trip_shows_with_its_meaning_on_the_overview_and_in_the_drive_history(
    page: BrowserPage,
) -> None:
    async with online_bench(HALL) as bench:
        p = page.page
        for node, hz in SPEEDS.items():
            bench.set_ramp("hall", node, 2.0)
            await bench.start("hall", node, hz)
        await p.goto(bench.url)
        await expect(p.locator(DRIVES_ROWS)).to_have_count(len(keys(HALL)), timeout=WAIT_MS)
        for node in SPEEDS:
            cell = row(p, f"hall/{node}").locator('[data-field="state"]')
            await expect(cell).to_have_text("running", timeout=WAIT_MS)

        bench.trip("hall", 3, 7)  # E07, over-voltage
        await wait_for(
            lambda: bench.snapshot("hall", 3).trip is not None, "the trip named", timeout=WAIT_S
        )
        trip = (await bench.get_json("api/v1/drives/hall/3"))["trip"]
        assert trip["code"] == "E07"
        assert trip["meaning"]
        tripped = row(p, "hall/3")
        await expect(tripped.locator('[data-field="trip"]')).to_contain_text(trip["code"])
        await expect(tripped.locator('[data-field="trip"]')).to_contain_text(trip["meaning"])
        await expect(tripped.locator('[data-field="state"]')).to_have_text("tripped")
        await expect(tripped).to_have_class("tripped")
        for key in keys(HALL):
            if key != "hall/3":
                await expect(row(p, key).locator('[data-field="trip"]')).to_have_text("")
        await screenshot(p, "workbench-overview.png")

        # The drive's page, by the overview's link: the trip, and the history the gateway read.
        await tripped.locator('[data-field="line"] a').click()
        await expect(p).to_have_url(f"{bench.url}#/drive/hall/3")
        await expect(p.locator('[data-field="title"]')).to_have_text("hall · node 3")
        await expect(p.locator('[data-field="state"]')).to_have_text("tripped")
        await expect(p.locator('[data-field="trip"]')).to_have_text(
            f"{trip['code']} {trip['meaning']}"
        )
        history = await bench.get_json("api/v1/drives/hall/3/trips")
        assert history["total_count"] == 1  # a new drive's first trip
        assert history["records"][0]["code"] == trip["code"]
        assert history["records"][0]["meaning"] == trip["meaning"]
        await expect(p.locator(TRIPS_ROWS)).to_have_count(len(history["records"]), timeout=WAIT_MS)
        newest = p.locator(TRIPS_ROWS).first
        await expect(newest.locator('[data-field="code"]')).to_have_text(trip["code"])
        await expect(newest.locator('[data-field="meaning"]')).to_have_text(trip["meaning"])
        await expect(newest.locator('[data-field="output_frequency_hz"]')).to_have_text(
            fixed(history["records"][0]["output_frequency_hz"], 2)
        )

        # Reset and started again: the trip clears, the history keeps it, the trend shows it all.
        bench.reset("hall", 3)
        await bench.start("hall", 3, 40.0)
        await expect(p.locator('[data-field="state"]')).to_have_text("running", timeout=WAIT_MS)
        await expect(p.locator('[data-field="trip"]')).to_have_text("none")
        await expect(newest.locator('[data-field="code"]')).to_have_text(trip["code"])
        await expect(newest.locator('[data-field="meaning"]')).to_have_text(trip["meaning"])
        await screenshot(p, "workbench-drive.png")
        page.assert_no_errors()


# The chart's plotting area: how many of its pixels are drawn in each series' colour (within
# the anti-aliasing's blend), and the leftmost and rightmost column drawn in any of them (the
# series cross and overlap, a later one drawn over an earlier: no one series spans it all).
COUNT_PIXELS: Final = """(colours) => {
    const u = window.workbench.chart;
    const {left, top, width, height} = u.bbox;
    const pixels = u.ctx.getImageData(left, top, width, height).data;
    const counts = colours.map(() => 0);
    let first = Infinity, last = -Infinity;
    for (let i = 0; i < pixels.length; i += 4) {
        if (pixels[i + 3] < 200) continue;
        colours.forEach(([r, g, b], k) => {
            const off = Math.abs(pixels[i] - r) + Math.abs(pixels[i + 1] - g)
                + Math.abs(pixels[i + 2] - b);
            if (off <= 48) {
                counts[k] += 1;
                const x = (i / 4) % width;
                first = Math.min(first, x);
                last = Math.max(last, x);
            }
        });
    }
    return {counts, first, last, width};
}"""


def trend_rows(trend: Mapping[str, list[Any]]) -> list[tuple[Any, ...]]:
    names = ("time", "output_frequency_hz", "output_current_a", "output_voltage_v")
    return list(zip(*(trend[name] for name in names), strict=True))


async def test_the_trend_draws_the_samples_the_api_reports(page: BrowserPage) -> None:
    async with online_bench(HALL) as bench:
        p = page.page
        await bench.start("hall", 1, 30.0)
        await wait_for(
            lambda: (bench.snapshot("hall", 1).output_frequency_hz or 0) > 0, "hall/1 turning"
        )
        async with p.expect_response(lambda r: r.url.endswith("/drives/hall/1/trend")) as loading:
            await p.goto(f"{bench.url}#/drive/hall/1")
        loaded = len((await (await loading.value).json())["time"])
        live = 8  # samples the page adds from the event stream after the trend it loaded
        await p.wait_for_function(
            "n => window.workbench.chart && window.workbench.chart.data[0].length >= n",
            arg=loaded + live,
            timeout=WAIT_MS,
        )
        chart = await p.evaluate("window.workbench.chart.data.map((column) => Array.from(column))")
        trend = await bench.get_json("api/v1/drives/hall/1/trend")

        drawn = list(zip(*chart, strict=True))
        last = drawn[-1][0]
        reported = [r for r in trend_rows(trend) if r[0] <= last]
        assert len(reported) >= loaded + live
        assert drawn == reported  # same times, same Hz, A and V, none missing, none added
        assert any(hz > 0 for _, hz, _, _ in drawn)  # the ramp, not only the stopped drive

        # ... and drawn: each series' colour on the canvas, the lines across the whole plot.
        await p.wait_for_function(
            f"colours => ({COUNT_PIXELS})(colours).counts.every((n) => n >= 50)",
            arg=SERIES_RGB,
            timeout=WAIT_MS,
        )
        pixels = await p.evaluate(COUNT_PIXELS, SERIES_RGB)
        assert all(n >= 50 for n in pixels["counts"]), pixels
        assert pixels["last"] - pixels["first"] >= 0.95 * pixels["width"], pixels
        page.assert_no_errors()


async def test_the_page_needs_nothing_but_the_gateway_and_its_csv_is_the_trend(
    page: BrowserPage,
) -> None:
    async with online_bench(HALL) as bench:
        p = page.page
        requested: list[str] = []
        p.on("request", lambda request: requested.append(request.url))
        await bench.start("hall", 1, 30.0)

        await p.goto(bench.url)
        await expect(p.locator(DRIVES_ROWS)).to_have_count(len(keys(HALL)), timeout=WAIT_MS)
        await row(p, "hall/1").locator('[data-field="line"] a').click()
        await expect(p.locator('[data-field="title"]')).to_have_text("hall · node 1")
        await p.wait_for_function(
            "() => window.workbench.chart && window.workbench.chart.data[0].length >= 10",
            timeout=WAIT_MS,
        )
        async with p.expect_download() as downloading:
            await p.get_by_test_id("csv").click()
        download = await downloading.value
        assert download.suggested_filename == "hall-1-trend.csv"
        assert await download.failure() is None
        saved = await download.path()
        text = Path(saved).read_text(encoding="utf-8")
        trend = await bench.get_json("api/v1/drives/hall/1/trend")

        table = list(csv.reader(io.StringIO(text, newline="")))
        assert table[0] == [
            "time_utc", "time_unix", "output_frequency_hz", "output_current_a", "output_voltage_v"
        ]  # fmt: skip
        body = table[1:]
        assert len(body) >= 10
        reported = trend_rows(trend)[: len(body)]
        for line, (at, hz, amps, volts) in zip(body, reported, strict=True):
            assert line[1] == f"{at:.3f}"
            assert [float(v) if v else None for v in line[2:]] == [hz, amps, volts]
            stamp = datetime.fromisoformat(line[0])  # ISO 8601 in UTC, to the millisecond
            assert stamp.utcoffset() == timedelta(0)
            assert abs(stamp.timestamp() - at) <= 0.001  # time_unix rounds, time_utc truncates

        page.assert_no_errors()
        assert any(url.endswith("/api/v1/events") for url in requested), requested
        assert any("/static/vendor/uplot/" in url for url in requested), requested
        elsewhere = [url for url in requested if not url.startswith(bench.url)]
        assert not elsewhere, f"the page asked for what the gateway does not serve: {elsewhere}"
