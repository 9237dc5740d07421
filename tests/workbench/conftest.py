"""Fixtures of the workbench's browser tests: a chromium and a page per test.

Function-scoped, as the suite's event loops are: Playwright's objects
belong to the loop that made them. Without chromium the fixture fails (the
suite never skips a test for a missing tool), naming the package to install.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Final

import pytest
from playwright.async_api import Browser, ConsoleMessage, Error, ViewportSize

from workbench.browser import BrowserPage, chromium_missing, launch_chromium

# the size the workbench page is laid out for
VIEWPORT: Final[ViewportSize] = {"width": 1280, "height": 800}


@pytest.fixture
async def browser() -> AsyncIterator[Browser]:
    missing = chromium_missing()
    if missing is not None:
        pytest.fail(missing, pytrace=False)
    async with launch_chromium() as launched:
        yield launched


@pytest.fixture
async def page(browser: Browser) -> AsyncIterator[BrowserPage]:
    context = await browser.new_context(viewport=VIEWPORT)
    try:
        opened = BrowserPage(await context.new_page())

        def on_console(message: ConsoleMessage) -> None:
            if message.type == "error":
                location = message.location
                opened.errors.append(
                    f"console: {message.text} ({location['url']}:{location['lineNumber']})"
                )

        def on_page_error(error: Error) -> None:
            opened.errors.append(f"uncaught: {error.name}: {error.message}")

        opened.page.on("console", on_console)
        opened.page.on("pageerror", on_page_error)
        yield opened
    finally:
        await context.close()
