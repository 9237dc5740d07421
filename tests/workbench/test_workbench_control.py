"""Control from the workbench page, in a real browser: the lease, the login, the refusals.

Each test starts its own gateway (HTTP on a free loopback port) polling a
simulated SJ300 line served over TCP, and drives Debian's chromium through
the page as an operator would: log in through the page's form, take
control, set a frequency, run, stop, close the tab. What must hold:

- a page that holds control and is closed stops its drive once the lease
  runs out, and no later than one transaction after that;
- a page left open keeps the lease by its heartbeats (three lease periods
  here) until the operator stops the drive;
- nobody writes without logging in, and no page of another origin writes
  through the operator's logged-in browser (CSRF);
- a gateway that grants no writes (or names nobody who may make them)
  offers none: no login, no control, no write route (POST
  /api/v1/parameters/check, which writes nothing, is not one).

The gateway's write routes see the gateway through :class:`Timestamped`,
which notes the loop time of every lease heartbeat it renewed: the time
from the page's last heartbeat to the drive's stop is measured on the
gateway's own clock, not guessed from the browser's side.

With ``SJ300_SCREENSHOTS=1`` in the environment, the hold test also saves
the guide's screenshot of a drive's page with its control section
(docs/guide/images/workbench-control.png).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import os
import re
import textwrap
from collections.abc import AsyncIterator, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import pytest
from aiohttp import web
from playwright.async_api import Locator, Page, Response, expect
from waiting import wait_for

from sj300_async.gateway import (
    AuditLog,
    Gateway,
    GatewayConfig,
    GatewayDrive,
    GatewayLine,
    Heartbeat,
    WriteRequest,
    WriteResult,
    parse_config,
)
from sj300_async.gateway.http import hash_password
from sj300_async.gateway.http._northbound import HttpNorthbound
from sj300_async.gateway.recorder import TripStore
from sj300_async.simulator import RunState, serve_tcp
from sj300_async.simulator.sj300 import SimulatedBus
from workbench.browser import BrowserPage

if TYPE_CHECKING:
    from prometheus_client.core import Metric

#: The lease: short, so that a lapse comes quickly; the page renews it every third of it.
LEASE_S: Final = 1.0
#: The line's poll interval: a transaction at this rate is a few milliseconds long.
INTERVAL_S: Final = 0.1
#: How late after the lease ran out the lapse's stop may reach the drive. The stop
#: jumps the line's queue: it waits at most for the transaction on the wire (a poll,
#: about 10 ms at 19200 baud) and takes one of its own, so a few tens of
#: milliseconds is the rule. Half a second leaves room for a loaded 2-core machine
#: running the browser beside the gateway, and none for a second lease period.
LAPSE_MARGIN_S: Final = 0.5
PASSWORD: Final = "correct horse battery"
#: Made once (scrypt costs tens of milliseconds).
PASSWORD_HASH: Final = hash_password(PASSWORD)
#: The simulated drives' states that mean the output runs up or at speed.
MOVING: Final = (RunState.ACCELERATING, RunState.CONSTANT_SPEED)
#: Where the guide's screenshot goes, when SJ300_SCREENSHOTS=1.
IMAGES: Final = Path(__file__).resolve().parents[2] / "docs" / "guide" / "images"
#: Every route that writes (POST); none of them exists on a read-only gateway.
WRITE_PATHS: Final = (
    "/api/v1/login",
    "/api/v1/logout",
    "/api/v1/drives/hall/1/lease",
    "/api/v1/drives/hall/1/run",
    "/api/v1/drives/hall/1/stop",
    "/api/v1/drives/hall/1/frequency",
    "/api/v1/drives/hall/1/parameter",
)
#: What chromium logs for a fetch the server refused with 401 (a test's own refused write).
UNAUTHORIZED: Final = re.compile(r"status of 401 \(Unauthorized\)")


def config_text(
    url: str, *, users: bool = True, grants: bool = True, on_lapse: str = "stop"
) -> str:
    """Line "hall": drives 1..4 polled every :data:`INTERVAL_S`, control granted on 1 and 2."""
    user = f'[[http.users]]\nname = "alice"\npassword_hash = "{PASSWORD_HASH}"\n'
    writes = '[[lines.writes]]\nnodes = "1-2"\ncontrol = true\n'
    return (
        textwrap.dedent(
            """
            [gateway]
            id = "hall-gw"
            [http]
            listen = "127.0.0.1:0"
            """
        )
        + (user if users else "")
        + textwrap.dedent(
            f"""
            [[lines]]
            name = "hall"
            url = "{url}"
            nodes = "1-4"
            interval_s = {INTERVAL_S}
            lease_s = {LEASE_S}
            on_lapse = "{on_lapse}"
            """
        )
        + (writes if grants else "")
    )


@dataclass(frozen=True, slots=True)
class Renewal:
    """A heartbeat the gateway renewed a lease by: its loop time, the client, the node."""

    at: float
    client: str
    node: int


class Timestamped:
    """The gateway as the write routes see it, noting each lease heartbeat it renewed."""

    def __init__(self, gateway: Gateway, renewals: list[Renewal]) -> None:
        self._gateway = gateway
        self._renewals = renewals

    @property
    def config(self) -> GatewayConfig:
        return self._gateway.config

    @property
    def audit(self) -> AuditLog:
        return self._gateway.audit

    @property
    def trip_records(self) -> TripStore | None:
        return self._gateway.trip_records

    @property
    def lines(self) -> Sequence[GatewayLine]:
        return self._gateway.lines

    @property
    def drives(self) -> Sequence[GatewayDrive]:
        return self._gateway.drives

    def drive(self, line: str, node: int) -> GatewayDrive | None:
        return self._gateway.drive(line, node)

    async def write(
        self,
        client: str,
        drive: GatewayDrive,
        request: WriteRequest,
        *,
        connection: str | None = None,
    ) -> WriteResult:
        result = await self._gateway.write(client, drive, request, connection=connection)
        if isinstance(request, Heartbeat) and result.refusal is None:
            # A heartbeat is judged and renewed without a pause: this is its time.
            at = asyncio.get_running_loop().time()
            self._renewals.append(Renewal(at, client, drive.node))
        return result

    async def read_parameter_raw(self, drive: GatewayDrive, code: str) -> int:
        return await self._gateway.read_parameter_raw(drive, code)

    def disconnected(self, connection: str) -> None:
        self._gateway.disconnected(connection)

    def refused(
        self, client: str, drive: GatewayDrive, what: str, value: object, result: WriteResult
    ) -> None:
        self._gateway.refused(client, drive, what, value, result)

    def metrics(self) -> Iterable[Metric]:
        return self._gateway.metrics()

    def problems(self) -> list[str]:
        return self._gateway.problems()


@dataclass
class Bench:
    """A running gateway on a simulated line, and the heartbeats it renewed."""

    gateway: Gateway
    sim: SimulatedBus
    base: str
    renewals: list[Renewal] = field(default_factory=list)

    def state(self, node: int) -> RunState:
        """What the simulated drive *node* is doing now."""
        return self.sim.drives[node].state(asyncio.get_running_loop().time())

    def drive(self, node: int) -> GatewayDrive:
        found = self.gateway.drive("hall", node)
        assert found is not None
        return found

    def drive_url(self, node: int = 1) -> str:
        return f"{self.base}/#/drive/hall/{node}"


@contextlib.asynccontextmanager
async def workbench(
    *, users: bool = True, grants: bool = True, on_lapse: str = "stop"
) -> AsyncIterator[Bench]:
    """A gateway on drives 1..4 served over TCP (enter it in the test's own task)."""
    sim = SimulatedBus(range(1, 5))
    for drive in sim.drives.values():
        # 2 s between 0 Hz and the maximum (50 Hz), both ways (factory: 30 s): a drive
        # reaches 20 Hz, and stops from it, in 0.8 s.
        drive.set_parameter("F002", 200)
        drive.set_parameter("F003", 200)
    server = await serve_tcp(sim)
    async with server:
        text = config_text(
            f"tcp://127.0.0.1:{server.port}", users=users, grants=grants, on_lapse=on_lapse
        )
        async with Gateway(parse_config(text, "test.toml")) as gateway:
            northbound = gateway.northbounds["http"]
            assert isinstance(northbound, HttpNorthbound)
            bench = Bench(gateway, sim, f"http://127.0.0.1:{northbound.port}")
            if northbound.writes is not None:
                northbound.writes.gateway = Timestamped(gateway, bench.renewals)
            yield bench


# -- the page, as an operator uses it ----------------------------------------------------------


def values_field(page: Page, name: str) -> Locator:
    return page.get_by_test_id("values").locator(f'[data-field="{name}"]')


def status_value(page: Page, name: str) -> Locator:
    """The value cell of the drive page's status row *name*."""
    return page.locator(
        f'[data-testid="status"] tr:has(td[data-field="name"]:text-is("{name}"))'
        ' td[data-field="value"]'
    )


async def log_in(page: Page, bench: Bench) -> None:
    """Open drive 1's page, follow "Log in", log in through the form: back on drive 1's page."""
    await page.goto(bench.drive_url(1))
    user = page.get_by_test_id("user")
    await user.get_by_role("link", name="Log in").click()
    await expect(page).to_have_url(re.compile(r"#/login$"))
    form = page.get_by_test_id("login-form")
    await form.locator('input[name="name"]').fill("alice")
    await form.locator('input[name="password"]').fill(PASSWORD)
    await form.get_by_role("button", name="Log in").click()
    await expect(user).to_contain_text("alice")
    await expect(page).to_have_url(re.compile(r"#/drive/hall/1$"))


async def take_and_run(page: Page, bench: Bench, hz: float = 20.0) -> str:
    """Take control of drive 1, set *hz*, run forward; the lease holder's name (the tab's)."""
    control = page.get_by_test_id("control")
    await expect(control).to_be_visible()
    await control.get_by_test_id("take").click()
    await expect(control.get_by_test_id("lease")).to_contain_text("You have control")
    await control.get_by_test_id("hz").fill(f"{hz:g}")
    await control.get_by_test_id("set-frequency").click()
    await expect(values_field(page, "set_frequency_hz")).to_have_text(f"{hz:.2f}")
    await control.get_by_test_id("run-forward").click()
    await expect(status_value(page, "running")).to_have_text("yes")
    await wait_for(lambda: bench.state(1) in MOVING, "drive 1 running")
    await expect(control.get_by_test_id("control-error")).to_have_text("")
    tab = await page.evaluate("window.workbench.tab")
    assert isinstance(tab, str)
    holder = f"http:alice#{tab}"
    assert bench.drive(1).lease.holder == holder
    return holder


def stop_records(audit: AuditLog) -> list[dict[str, object]]:
    """The audit log's stops: carried out (a command, new "stop"), or refused (what "stop")."""
    return [r for r in audit.recent if r["new"] == "stop" or r["what"] == "stop"]


def last_renewal(bench: Bench, holder: str) -> float:
    return max(r.at for r in bench.renewals if r.client == holder and r.node == 1)


# -- the lease -----------------------------------------------------------------------------------


async def test_a_closed_page_stops_its_drive_when_the_lease_runs_out(page: BrowserPage) -> None:
    loop = asyncio.get_running_loop()
    async with workbench() as bench:
        await log_in(page.page, bench)
        holder = await take_and_run(page.page, bench)
        page.assert_no_errors()
        closed = loop.time()
        await page.page.close()
        # No more heartbeats: the lease runs out, and the lapse's stop reaches the drive.
        await wait_for(
            lambda: bench.state(1) not in MOVING,
            "the lapse's stop reaching drive 1",
            timeout=LEASE_S + 5,
        )
        stopped = loop.time()
        last = last_renewal(bench, holder)
        assert closed - last < LEASE_S  # the page renewed its lease until it was closed
        lapse = stopped - last
        print(f"from the last heartbeat to the stop: {lapse:.3f} s (lease {LEASE_S} s)")
        assert LEASE_S <= lapse < LEASE_S + LAPSE_MARGIN_S
        await wait_for(
            lambda: any(
                r["what"] == "lease lapsed: stop"
                and r["client"] == holder
                and str(r["new"]).startswith("confirmed stopped")
                for r in bench.gateway.audit.recent
            ),
            "the lapse audited, its stop confirmed",
        )
        assert bench.drive(1).lease.holder is None


async def test_an_open_page_keeps_control_until_it_stops_the_drive(page: BrowserPage) -> None:
    p = page.page
    async with workbench() as bench:
        await log_in(p, bench)
        holder = await take_and_run(p, bench)
        held_from = asyncio.get_running_loop().time()
        # A measured hold, not a wait for a state: three lease periods with the page open.
        await p.wait_for_timeout(3 * LEASE_S * 1000)
        held_until = asyncio.get_running_loop().time()
        assert bench.state(1) in MOVING, "the drive stopped while its page was open"
        assert bench.drive(1).lease.holder == holder
        times = [held_from] + [
            r.at for r in bench.renewals if r.client == holder and held_from <= r.at
        ]
        gaps = [b - a for a, b in itertools.pairwise([*times, held_until])]
        # Every lease_s / 3 (0.33 s): about 9 in the hold, and no gap the lease ran out in.
        assert len(gaps) >= 6, gaps
        assert max(gaps) < LEASE_S, gaps
        await expect(p.get_by_test_id("lease")).to_contain_text("You have control")
        if os.environ.get("SJ300_SCREENSHOTS") == "1":
            IMAGES.mkdir(parents=True, exist_ok=True)
            await p.screenshot(path=IMAGES / "workbench-control.png", full_page=True)

        await p.get_by_test_id("control").get_by_test_id("stop").click()
        await wait_for(lambda: bench.state(1) not in MOVING, "drive 1 stopping")
        await expect(status_value(p, "running")).to_have_text("no")
        await expect(p.get_by_test_id("control-error")).to_have_text("")
        stops = stop_records(bench.gateway.audit)
        assert [(r["client"], r["result"]) for r in stops] == [(holder, "ok")]
        assert not any("lapsed" in str(r["what"]) for r in bench.gateway.audit.recent)
        page.assert_no_errors()
        await p.close()  # before the gateway stops: no reconnecting page in its way


# -- who may write --------------------------------------------------------------------------------


async def test_without_a_login_the_page_offers_no_control_and_a_write_is_refused(
    page: BrowserPage,
) -> None:
    p = page.page
    async with workbench() as bench:
        await p.goto(bench.drive_url(1))
        await expect(p.get_by_test_id("user").get_by_role("link", name="Log in")).to_be_visible()
        await expect(values_field(p, "online")).to_have_text("online")
        await expect(p.get_by_test_id("control")).to_be_hidden()
        answer = await p.evaluate(
            """async (url) => {
                const response = await fetch(url, {
                    method: "POST",
                    headers: { "Content-Type": "application/json" },
                    body: JSON.stringify({ tab: window.workbench.tab, direction: "forward" }),
                });
                return { status: response.status, body: await response.json() };
            }""",
            f"{bench.base}/api/v1/drives/hall/1/run",
        )
        assert answer["status"] == 401
        assert "log in first" in answer["body"]["error"]
        assert bench.state(1) == RunState.STOPPED
        assert list(bench.gateway.audit.recent) == []  # refused at the door
        # The one error: chromium logs the refused fetch's 401.
        assert [e for e in page.errors if not UNAUTHORIZED.search(e)] == []
        await p.close()


def elsewhere_pages(stop_url: str) -> web.Application:
    """Another site's pages, each trying to stop drive 1 through the visitor's browser."""
    fetches = textwrap.dedent(
        f"""\
        <!doctype html>
        <html lang="en"><head><meta charset="utf-8"><title>elsewhere</title>
        <link rel="icon" href="data:,"></head>
        <body><pre id="cors">pending</pre><pre id="no-cors">pending</pre>
        <script>
        async function attempt(id, init) {{
          const out = document.getElementById(id);
          try {{
            const response = await fetch("{stop_url}", init);
            out.textContent = `resolved ${{response.type}} ${{response.status}}`;
          }} catch (error) {{
            out.textContent = `rejected ${{error.name}}: ${{error.message}}`;
          }}
        }}
        // The page's own kind of request: JSON, so the browser asks first (CORS preflight).
        attempt("cors", {{method: "POST", credentials: "include",
          headers: {{"Content-Type": "application/json"}}, body: "{{}}"}});
        // A "simple" request the browser sends without asking; its answer stays opaque.
        attempt("no-cors", {{method: "POST", mode: "no-cors", credentials: "include",
          headers: {{"Content-Type": "text/plain"}}, body: '{{"tab": "x"}}'}});
        </script></body></html>
        """
    )
    form = textwrap.dedent(
        f"""\
        <!doctype html>
        <html lang="en"><head><meta charset="utf-8"><title>elsewhere</title>
        <link rel="icon" href="data:,"></head>
        <body><form id="f" method="post" action="{stop_url}">
        <input type="hidden" name="tab" value="x"></form>
        <script>document.getElementById("f").submit();</script></body></html>
        """
    )

    def serve(html: str) -> Any:
        async def handler(request: web.Request) -> web.Response:
            return web.Response(text=html, content_type="text/html")

        return handler

    app = web.Application()
    app.router.add_get("/fetch", serve(fetches))
    app.router.add_get("/form", serve(form))
    return app


@contextlib.asynccontextmanager
async def serving(app: web.Application) -> AsyncIterator[int]:
    """*app* on a free loopback port (its number), stopped at the end."""
    runner = web.AppRunner(app)
    await runner.setup()
    try:
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        assert runner.addresses, "the server is listening nowhere"
        yield int(runner.addresses[0][1])
    finally:
        await runner.cleanup()


@pytest.mark.parametrize(
    "host",
    [
        # Same site (cookies go by host, not port: the session cookie is sent along),
        # another origin: the Origin check alone refuses it.
        "127.0.0.1",
        # Another site: SameSite=Strict keeps the cookie home, and the Origin check refuses.
        "localhost",
    ],
)
async def test_another_origin_cannot_write_through_a_logged_in_browser(
    page: BrowserPage, host: str
) -> None:
    p = page.page
    # "hold": a lapse sends nothing, so the drive runs on whatever the page's heartbeats do
    # while it is in a background tab; only a write that got through could stop it.
    async with workbench(on_lapse="hold") as bench:
        await log_in(p, bench)
        await take_and_run(p, bench)
        stop_url = f"{bench.base}/api/v1/drives/hall/1/stop"
        async with serving(elsewhere_pages(stop_url)) as port:
            other = await p.context.new_page()
            seen: list[Response] = []
            other.on("response", lambda r: seen.append(r) if r.url == stop_url else None)

            def the_post(response: Response) -> bool:
                return response.url == stop_url and response.request.method == "POST"

            async with other.expect_response(the_post) as fetched:
                await other.goto(f"http://{host}:{port}/fetch")
            no_cors = await fetched.value
            # The JSON fetch never leaves the browser: its CORS preflight finds nothing
            # that allows it (no Access-Control-Allow-Origin), so it rejects in the script.
            await expect(other.locator("#cors")).to_have_text(
                re.compile(r"^rejected TypeError: Failed to fetch")
            )
            await expect(other.locator("#no-cors")).to_have_text("resolved opaque 0")
            async with other.expect_response(the_post) as submitted:
                await other.goto(f"http://{host}:{port}/form")
            form = await submitted.value
            headers = await form.request.all_headers()
            # The browser keeps no body of an opaque answer: its status says enough.
            answer = await form.text()
            print(
                f"from {host}:{port}: no-cors fetch {no_cors.status}, form {form.status} {answer}"
            )
            assert (no_cors.status, form.status) == (403, 403)
            assert "another site" in answer
            # The form's request as the browser sent it (a fetch's opaque one it does not
            # show whole): the session cookie along from the same site, not from another.
            assert headers["origin"] == f"http://{host}:{port}"
            assert ("sj300_session=" in headers.get("cookie", "")) is (host == "127.0.0.1")
            # Those two, and no POST of the JSON fetch.
            assert [r.request.method for r in seen].count("POST") == 2
            await other.close()
        assert bench.state(1) in MOVING, "a page of another origin stopped the drive"
        assert stop_records(bench.gateway.audit) == []
        assert {r["result"] for r in bench.gateway.audit.recent} == {"ok"}
        page.assert_no_errors()  # the gateway's page (the other one's are its own business)
        await p.close()


# -- a gateway that grants no writes -----------------------------------------------------------


@pytest.mark.parametrize(
    ("users", "grants"), [(True, False), (False, True)], ids=["no-grants", "no-users"]
)
async def test_a_read_only_gateway_offers_no_writes(
    page: BrowserPage, users: bool, grants: bool
) -> None:
    p = page.page
    async with workbench(users=users, grants=grants) as bench:
        await p.goto(bench.drive_url(1))
        await expect(p.get_by_test_id("gateway")).to_contain_text("hall-gw")
        await expect(values_field(p, "online")).to_have_text("online")
        assert await p.evaluate("window.workbench.state.gateway.writes") is False
        await expect(p.get_by_test_id("user")).to_have_text("")
        await expect(p.get_by_test_id("control")).to_be_hidden()
        statuses = {}
        for path in WRITE_PATHS:
            response = await p.request.post(
                bench.base + path, data={"tab": "x"}, headers={"Origin": bench.base}
            )
            statuses[path] = response.status
        assert all(status in (404, 405) for status in statuses.values()), statuses
        assert list(bench.gateway.audit.recent) == []
        page.assert_no_errors()
        await p.close()
