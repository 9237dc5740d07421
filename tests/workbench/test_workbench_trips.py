"""The workbench's Trips pages (issue 45) in Debian's chromium, on a gateway whose
simulated drive trips: the list, a record with its chart (the trip's instant marked), its
downloads, and the drive page's link to its records. No console error on the way.

With ``SJ300_SCREENSHOTS=1`` it saves docs/guide/trips.md's screenshots.
"""

from __future__ import annotations

from typing import Final

from playwright.async_api import expect
from waiting import wait_for

from workbench.browser import BrowserPage
from workbench.gateway import workbench_gateway
from workbench.test_workbench_pages import WAIT_MS, WAIT_S, screenshot

#: A short window: the record is kept a second after the trip.
RECORDER: Final = "[recorder]\nbefore_s = 4\nafter_s = 1\n"
#: The marker's colour (static/trips.js): a dashed red line at the trip's instant.
MARKER_RGB: Final = (0xC9, 0x2A, 0x2A)

# The chart's canvas, looked at around the trip's instant: whether the marker's red is there.
MARKED: Final = """([r, g, b]) => {
    const chart = window.workbench.tripChart;
    const record = chart.data[0];
    const canvas = chart.ctx.canvas;
    const at = window.workbench.tripTime;
    const x = Math.round(chart.valToPos(at, "x", true));
    const top = Math.round(chart.bbox.top), height = Math.round(chart.bbox.height);
    const pixels = chart.ctx.getImageData(x - 3, top, 7, height).data;
    let red = 0;
    for (let i = 0; i < pixels.length; i += 4) {
        if (Math.abs(pixels[i] - r) < 24 && Math.abs(pixels[i + 1] - g) < 24
            && Math.abs(pixels[i + 2] - b) < 24) red += 1;
    }
    return { red, samples: record.length, width: canvas.width };
}"""


async def test_the_trips_pages_show_a_record_with_its_chart(page: BrowserPage) -> None:
    async with workbench_gateway({"hall": range(1, 3)}, RECORDER) as bench:
        gateway, p = bench.gateway, page.page
        await wait_for(
            lambda: all(d.snapshot.available for d in gateway.drives), "online", timeout=WAIT_S
        )
        bench.set_ramp("hall", 1, 2.0)
        await bench.start("hall", 1, 40.0)
        drive = gateway.drive("hall", 1)
        assert drive is not None
        assert drive.trend is not None
        trend = drive.trend
        await wait_for(lambda: len(trend) > 25, "five seconds of samples", timeout=WAIT_S)
        bench.trip("hall", 1, 7)
        store = gateway.trip_records
        assert store is not None
        await wait_for(lambda: len(store) == 1, "the record kept", timeout=WAIT_S)
        (summary,) = store.summaries()

        await p.goto(f"{bench.url}#/drive/hall/1")
        await p.locator('[data-testid="drive-trips"]').click()
        await expect(p).to_have_url(f"{bench.url}#/trips/hall/1")
        rows = p.locator('[data-testid="trip-list"] tbody tr')
        await expect(rows).to_have_count(1, timeout=WAIT_MS)
        await expect(rows.locator('[data-field="code"]')).to_have_text("E07")
        await expect(rows.locator('[data-field="meaning"]')).to_have_text(summary.meaning or "")
        await p.goto(f"{bench.url}#/trips")
        await expect(rows).to_have_count(1, timeout=WAIT_MS)
        await screenshot(p, "trips-list.png")

        await rows.locator('[data-field="time"] a').click()
        await expect(p).to_have_url(f"{bench.url}#/trip/{summary.id}")
        await expect(p.locator('[data-testid="trip-name"]')).to_have_text(
            f"E07 {summary.meaning}", timeout=WAIT_MS
        )
        await p.wait_for_function("() => window.workbench.tripChart")
        await p.evaluate(f"() => {{ window.workbench.tripTime = {summary.time}; }}")
        drawn = await p.evaluate(MARKED, list(MARKER_RGB))
        record = await bench.get_json(f"api/v1/trips/{summary.id}")
        assert drawn["samples"] == len(record["samples"]["time"]) >= 20  # 5 s at 0.2 s
        assert drawn["red"] > 20, drawn  # the dashed marker down the plot at the trip
        for testid, path in (
            ("trip-json", f"/api/v1/trips/{summary.id}"),
            ("trip-csv", f"/api/v1/trips/{summary.id}.csv"),
            ("trip-pcapng", f"/api/v1/trips/{summary.id}/frames.pcapng"),
        ):
            link = p.locator(f'[data-testid="{testid}"]')
            await expect(link).to_have_attribute("href", path)
            async with bench.session.get(bench.url.rstrip("/") + path) as answer:
                assert answer.status == 200, path
        await expect(p.locator('[data-testid="trip-drive"]')).to_have_attribute(
            "href", "#/drive/hall/1"
        )
        await screenshot(p, "trip-record.png")
    page.assert_no_errors()
