"""The browser fixtures work: chromium loads a page from a local aiohttp server and runs its script.

A page of the test's own, served on 127.0.0.1, so that a failure here is the
browser set-up's, not the workbench's.
"""

from __future__ import annotations

from collections.abc import AsyncIterator

import pytest
from aiohttp import web
from playwright.async_api import expect

from workbench.browser import BrowserPage

PAGE = """<!doctype html>
<html lang="en">
<head><meta charset="utf-8"><title>smoke</title><link rel="icon" href="data:,"></head>
<body>
<button id="go">go</button>
<p id="out">waiting</p>
<script>
document.getElementById("go").addEventListener("click", () => {
  document.getElementById("out").textContent = "clicked";
});
</script>
</body>
</html>
"""


async def _index(request: web.Request) -> web.Response:
    return web.Response(text=PAGE, content_type="text/html")


@pytest.fixture
async def server_url() -> AsyncIterator[str]:
    app = web.Application()
    app.router.add_get("/", _index)
    runner = web.AppRunner(app)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", 0)
    await site.start()
    try:
        assert runner.addresses, "the server is listening nowhere"
        host, port = runner.addresses[0][:2]
        yield f"http://{host}:{port}/"
    finally:
        await runner.cleanup()


async def test_a_click_changes_the_text(page: BrowserPage, server_url: str) -> None:
    response = await page.page.goto(server_url)
    assert response is not None
    assert response.ok
    await expect(page.page.locator("#out")).to_have_text("waiting")

    await page.page.locator("#go").click()

    await expect(page.page.locator("#out")).to_have_text("clicked")
    page.assert_no_errors()


async def test_a_script_error_is_collected(page: BrowserPage, server_url: str) -> None:
    await page.page.goto(server_url)

    # the uncaught error comes after the evaluate returns: wait for it on the page
    async with page.page.expect_event("pageerror"):
        await page.page.evaluate("""() => {
            console.error("seen");
            setTimeout(() => { throw new Error("thrown"); });
        }""")

    assert [e.split(" (")[0] for e in page.errors] == ["console: seen", "uncaught: Error: thrown"]
