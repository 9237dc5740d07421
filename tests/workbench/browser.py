"""Debian's chromium, driven by Playwright: the workbench page's browser tests.

Playwright's own browser builds are downloaded by ``playwright install``,
which the project never runs (a plant's machines and CI reach the package
registries only): the tests launch the ``chromium`` Debian package instead
(``apt-get install chromium``; ``make system-packages`` installs it).
"""

from __future__ import annotations

import os
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

from playwright.async_api import Browser, Page, async_playwright

CHROMIUM: Final = Path("/usr/bin/chromium")

CHROMIUM_ARGS: Final = (
    # the tests run as root, where chromium's sandbox cannot start
    "--no-sandbox",
    # no GPU here: software rendering, without the GPU process's probing
    "--disable-gpu",
    # Debian's launcher turns remote extensions on (/etc/chromium.d/extensions) and
    # then leaves background networking on too: the browser would reach for Google
    # (field trials, component and extension updates, sync, QUIC probes), and on a
    # closed network each is a refused connection and an error in the log
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)


@dataclass
class BrowserPage:
    """The ``page`` fixture: a page, and what its scripts reported as errors.

    ``errors`` collects the console's errors and the uncaught exceptions, as
    they come; a test asserts there were none (:meth:`assert_no_errors`).
    """

    page: Page
    errors: list[str] = field(default_factory=list)

    def assert_no_errors(self) -> None:
        assert not self.errors, "the page reported errors:\n" + "\n".join(self.errors)


class ChromiumMissing(RuntimeError):
    """Debian's chromium is not installed: the browser tests cannot run."""


def chromium_missing() -> str | None:
    """Why the browser tests cannot run here, or ``None`` when chromium is installed."""
    if os.access(CHROMIUM, os.X_OK):
        return None
    return (
        f"{CHROMIUM} not found: the workbench's browser tests drive Debian's chromium"
        " (apt-get install chromium, or make system-packages)"
    )


@asynccontextmanager
async def launch_chromium() -> AsyncIterator[Browser]:
    """A headless chromium, closed on exit; :class:`ChromiumMissing` without one.

    Playwright's ``launch()`` gives the browser a fresh profile of its own
    (a temporary ``--user-data-dir``, removed when the browser closes), so
    no test sees another's cookies, storage or cache. Its objects belong to
    the event loop that made them: launch it in the test's own loop.
    """
    missing = chromium_missing()
    if missing is not None:
        raise ChromiumMissing(missing)
    async with async_playwright() as playwright:
        browser = await playwright.chromium.launch(
            executable_path=CHROMIUM, headless=True, args=list(CHROMIUM_ARGS)
        )
        try:
            yield browser
        finally:
            await browser.close()
