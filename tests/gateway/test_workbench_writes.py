"""Writes through the workbench: who may, how a browser is kept from being tricked, the lease.

A real gateway on a simulated line over TCP, a real aiohttp client. What
must hold: no write route without someone named who may write; a write
needs a session with its CSRF token from the same origin, or a token; a
run needs the lease, a stop does not; bad input is refused before the
gateway is asked and audited; a page that stops renewing its lease
stops the drive; TLS from the configuration's certificate.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import ssl
import subprocess
import sys
import textwrap
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest
from waiting import wait_for

from sj300_async.gateway import Gateway, GatewayConfigError, KeyedBudget, parse_config
from sj300_async.gateway.http import hash_password, hash_token
from sj300_async.gateway.http._auth import MAX_FAILURES, verify_password
from sj300_async.gateway.http._northbound import HttpNorthbound
from sj300_async.profiles import DriveSnapshot, ParameterBackup, get_profile
from sj300_async.simulator import RunState

from .conftest import SimLine

PASSWORD = "correct horse battery"
#: Made once (scrypt costs tens of milliseconds).
PASSWORD_HASH = hash_password(PASSWORD)
TOKEN = "t" * 43
LEASE_S = 1.0


def config_text(url: str, *, auth: bool = True, grants: bool = True, extra: str = "") -> str:
    users = (
        f"""
        [[http.users]]
        name = "alice"
        password_hash = "{PASSWORD_HASH}"
        [[http.tokens]]
        name = "report"
        token_hash = "{hash_token(TOKEN)}"
        """
        if auth
        else ""
    )
    writes = (
        """
        [[lines.writes]]
        nodes = "1-2"
        control = true
        """
        if grants
        else ""
    )
    return textwrap.dedent(
        f"""
        [http]
        listen = "127.0.0.1:0"
        {extra}
        {users}
        [[lines]]
        name = "hall"
        url = "{url}"
        nodes = "1-3"
        interval_s = 0.1
        lease_s = {LEASE_S}
        {writes}
        """
    )


def northbound(gateway: Gateway) -> HttpNorthbound:
    found = gateway.northbounds["http"]
    assert isinstance(found, HttpNorthbound)
    return found


class Page:
    """A browser-like client: its cookies, its CSRF token, its tab id."""

    def __init__(self, session: aiohttp.ClientSession, base: str) -> None:
        self.session = session
        self.base = base
        self.csrf = ""
        self.tab = "tab1"

    async def post(
        self, path: str, body: Any = None, *, headers: dict[str, str] | None = None
    ) -> tuple[int, Any]:
        sent = {"Content-Type": "application/json", "Origin": self.base}
        if self.csrf:
            sent["X-CSRF-Token"] = self.csrf
        sent |= headers or {}
        data = b"" if body is None else json.dumps(body).encode()
        async with self.session.post(self.base + path, data=data, headers=sent) as response:
            if response.content_type != "application/json":  # aiohttp's own 404, 405
                return response.status, await response.text()
            return response.status, await response.json()

    async def login(self, password: str = PASSWORD) -> tuple[int, Any]:
        status, answer = await self.post("/api/v1/login", {"name": "alice", "password": password})
        if status == 200:
            self.csrf = answer["csrf"]
        return status, answer

    async def control(self, node: int, what: str, **body: Any) -> tuple[int, Any]:
        return await self.post(f"/api/v1/drives/hall/{node}/{what}", {"tab": self.tab, **body})


@contextlib.asynccontextmanager
async def workbench(text: str) -> AsyncIterator[tuple[Gateway, Page]]:
    async with (
        Gateway(parse_config(text, "test.toml")) as gateway,
        # unsafe: keep cookies from an IP address, as a browser does (aiohttp's default does not)
        aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as session,
    ):
        yield gateway, Page(session, f"http://127.0.0.1:{northbound(gateway).port}")


def snapshot_of(gateway: Gateway, node: int) -> DriveSnapshot:
    drive = gateway.drive("hall", node)
    assert drive is not None
    return drive.snapshot


def state(gateway: Gateway, node: int) -> str | None:
    drive = gateway.drive("hall", node)
    assert drive is not None
    return drive.snapshot.state


# -- which routes exist ------------------------------------------------------------------------


@pytest.mark.parametrize(("auth", "grants"), [(False, True), (True, False), (False, False)])
async def test_without_someone_who_may_write_there_is_no_write_route(
    sim_line: SimLine, auth: bool, grants: bool, caplog: pytest.LogCaptureFixture
) -> None:
    async with workbench(config_text(sim_line.url, auth=auth, grants=grants)) as (_, page):
        for path in ("/api/v1/login", "/api/v1/drives/hall/1/run", "/api/v1/drives/hall/1/stop"):
            status, _ = await page.post(path, {})
            assert status in (404, 405), path
        async with page.session.get(page.base + "/api/v1/gateway") as response:
            assert (await response.json())["writes"] is False
    if grants and not auth:
        assert any("serves no writes" in r.getMessage() for r in caplog.records), _logging_state()


# -- who may write ------------------------------------------------------------------------------


async def test_a_write_needs_a_login_and_its_csrf_token(sim_line: SimLine) -> None:
    async with workbench(config_text(sim_line.url)) as (gateway, page):
        assert (await page.control(1, "stop"))[0] == 401
        assert (await page.login("wrong password"))[0] == 401
        login = {"name": "alice", "password": PASSWORD}
        async with page.session.post(
            page.base + "/api/v1/login", json=login, headers={"Origin": page.base}
        ) as response:
            # HttpOnly: a script cannot read it; SameSite=Strict: another site's page cannot
            # make the browser send it; no Secure over plain HTTP (it would never be sent).
            cookie = response.headers["Set-Cookie"]
            assert "HttpOnly" in cookie
            assert "SameSite=Strict" in cookie
            assert "Secure" not in cookie
        status, answer = await page.login()
        assert status == 200
        assert answer["user"] == "alice"
        async with page.session.get(page.base + "/api/v1/session") as response:
            assert (await response.json())["csrf"] == page.csrf
        csrf, page.csrf = page.csrf, ""
        status, answer = await page.control(1, "stop")
        assert status == 403
        assert "X-CSRF-Token" in answer["error"]
        page.csrf = "not-the-token"
        assert (await page.control(1, "stop"))[0] == 403
        page.csrf = csrf
        assert (await page.control(1, "stop")) == (
            200,
            {"ok": True, "client": "http:alice#tab1", "lease_s": LEASE_S},
        )
        # Logged out: the session is gone.
        assert (await page.post("/api/v1/logout", {}))[0] == 200
        assert (await page.control(1, "stop"))[0] == 401
    refused = [r for r in gateway.audit.recent if r["result"] != "ok"]
    assert refused == []  # refused at the door, before the gateway judged anything


@pytest.mark.parametrize(
    "headers",
    [
        {"Origin": "http://evil.example"},
        {"Origin": "null"},
        {"Sec-Fetch-Site": "cross-site"},
    ],
)
async def test_a_cross_site_write_is_refused(sim_line: SimLine, headers: dict[str, str]) -> None:
    async with workbench(config_text(sim_line.url)) as (gateway, page):
        await page.login()
        status, answer = await page.post(
            "/api/v1/drives/hall/1/stop", {"tab": "x"}, headers=headers
        )
        assert status == 403
        assert "another site" in answer["error"]
        # A stop carried out is audited as a command whose new value is "stop".
        assert not any("stop" in (r["what"], r["new"]) for r in gateway.audit.recent)


async def test_a_script_writes_with_its_token(sim_line: SimLine) -> None:
    async with workbench(config_text(sim_line.url)) as (gateway, page):
        bearer = {"Authorization": f"Bearer {TOKEN}"}
        status, answer = await page.post("/api/v1/drives/hall/2/stop", {}, headers=bearer)
        assert (status, answer["client"]) == (200, "http-token:report")
        wrong = {"Authorization": "Bearer " + "u" * 43}
        assert (await page.post("/api/v1/drives/hall/2/stop", {}, headers=wrong))[0] == 401
        basic = {"Authorization": "Basic YWxpY2U6eA=="}
        assert (await page.post("/api/v1/drives/hall/2/stop", {}, headers=basic))[0] == 401
    assert [r["client"] for r in gateway.audit.recent] == ["http-token:report"]


async def test_failed_logins_lock_the_address_out(sim_line: SimLine) -> None:
    async with workbench(config_text(sim_line.url)) as (gateway, page):
        writes = northbound(gateway).writes
        assert writes is not None
        # The lock is for the slow guesser the per-address budget lets through: here the
        # budget is made large enough not to refuse first.
        writes.budget = KeyedBudget(2 * MAX_FAILURES, 1.0)
        for _ in range(MAX_FAILURES):
            assert (await page.login("nope"))[0] == 401
        status, answer = await page.login()  # the right password, too late
        assert status == 429
        assert "too many failed logins" in answer["error"]


# -- control under the lease ------------------------------------------------------------------


async def test_run_needs_the_lease_and_stop_does_not(sim_line: SimLine) -> None:
    async with workbench(config_text(sim_line.url)) as (gateway, page):
        await page.login()
        status, answer = await page.control(1, "run", direction="forward")
        assert (status, answer["refusal"]) == (409, "no_lease")
        assert (await page.control(1, "lease"))[0] == 200
        assert (await page.control(1, "run", direction="forward"))[0] == 200
        await wait_for(lambda: state(gateway, 1) not in (None, "stopped"), "drive 1 running")
        other = Page(page.session, page.base)
        other.csrf, other.tab = page.csrf, "tab2"  # the same user's second tab
        status, answer = await other.control(1, "lease")
        assert (status, answer["refusal"]) == (409, "lease_held")
        assert (await other.control(1, "stop"))[0] == 200  # stop: anyone allowed to control
        status, answer = await page.control(3, "lease")
        assert (status, answer["refusal"]) == (403, "not_allowed")  # drive 3: no grant


@pytest.mark.parametrize(
    ("what", "body", "status", "refusal"),
    [
        ("run", {"direction": "sideways"}, 400, "malformed"),
        ("frequency", {"hz": "fast"}, 400, "malformed"),
        ("frequency", {"hz": True}, 400, "malformed"),
        ("frequency", {}, 400, "malformed"),
        ("frequency", {"hz": 1e9}, 422, "invalid_value"),
        ("frequency", {"hz": -1}, 422, "invalid_value"),
    ],
)
async def test_a_bad_value_is_refused_and_audited(
    sim_line: SimLine, what: str, body: dict[str, Any], status: int, refusal: str
) -> None:
    async with workbench(config_text(sim_line.url)) as (gateway, page):
        await page.login()
        await page.control(1, "lease")
        got, answer = await page.control(1, what, **body)
        assert (got, answer["refusal"]) == (status, refusal)
        assert answer["error"]
        assert gateway.audit.recent[-1]["reason"] == refusal
        loop = asyncio.get_running_loop()
        drive = sim_line.sim.drives[1]
        assert drive.state(loop.time()) == RunState.STOPPED  # nothing reached the drive
        assert drive.parameters["F001"] == 0


async def test_a_malformed_body_is_refused_before_anything(sim_line: SimLine) -> None:
    async with workbench(config_text(sim_line.url)) as (gateway, page):
        await page.login()
        url = page.base + "/api/v1/drives/hall/1/stop"
        headers = {"X-CSRF-Token": page.csrf, "Origin": page.base}
        cases = [
            ({"Content-Type": "application/json"}, b"{not json", 400),
            ({"Content-Type": "application/json"}, b"[1, 2]", 400),
            ({"Content-Type": "text/plain"}, b"{}", 415),
            ({"Content-Type": "application/json"}, b"{" + b" " * (10 * 1024 * 1024) + b"}", 413),
        ]
        for kind, data, status in cases:
            async with page.session.post(url, data=data, headers=headers | kind) as response:
                assert response.status == status, (kind, data[:20])
                assert "error" in await response.json(content_type=None)
        # A stop carried out is audited as a command whose new value is "stop".
        assert not any("stop" in (r["what"], r["new"]) for r in gateway.audit.recent)


async def test_a_page_that_stops_renewing_stops_the_drive(sim_line: SimLine) -> None:
    loop = asyncio.get_running_loop()
    drive = sim_line.sim.drives[2]
    moving = (RunState.ACCELERATING, RunState.CONSTANT_SPEED)
    async with workbench(config_text(sim_line.url)) as (gateway, page):
        await page.login()
        asked = loop.time()
        assert (await page.control(2, "lease"))[0] == 200
        heartbeat = loop.time()  # the heartbeat was taken between these two times
        assert (await page.control(2, "frequency", hz=20))[0] == 200
        assert (await page.control(2, "run", direction="forward"))[0] == 200
        assert drive.state(loop.time()) in moving
        # The page is closed: no more heartbeats. The lapse's stop reaches the drive.
        await wait_for(lambda: drive.state(loop.time()) not in moving, "drive 2 stopping")
        stopped = loop.time()
        # Not before the lease ran out; then within one transaction (ms-long ones, 0.1 s polls).
        assert stopped >= asked + LEASE_S
        assert stopped < heartbeat + LEASE_S + 0.5
        await wait_for(
            lambda: any("lapse" in str(r["what"]) for r in gateway.audit.recent),
            "the lapse audited",
        )


# -- HTTPS -----------------------------------------------------------------------------------


def _certificate(folder: Path) -> tuple[Path, Path]:
    cert, key = folder / "gateway.crt", folder / "gateway.key"
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
         "-subj", "/CN=127.0.0.1", "-addext", "subjectAltName=IP:127.0.0.1",
         "-keyout", str(key), "-out", str(cert)],
        check=True, capture_output=True,
    )  # fmt: skip
    return cert, key


async def test_https_from_the_configured_certificate(sim_line: SimLine, tmp_path: Path) -> None:
    cert, key = _certificate(tmp_path)
    tls = f'tls_cert = "{cert}"\ntls_key = "{key}"'
    async with Gateway(parse_config(config_text(sim_line.url, extra=tls), "test.toml")) as gateway:
        port = northbound(gateway).port
        assert northbound(gateway).announce() == (
            f"http on https://127.0.0.1:{port}/ (workbench, /metrics, /healthz)"
        )
        trust = ssl.create_default_context(cafile=str(cert))
        jar = aiohttp.CookieJar(unsafe=True)
        async with aiohttp.ClientSession(cookie_jar=jar) as session:
            async with session.get(f"https://127.0.0.1:{port}/healthz", ssl=trust) as response:
                assert response.status == 200
            page = Page(session, f"https://127.0.0.1:{port}")
            async with session.post(
                page.base + "/api/v1/login",
                json={"name": "alice", "password": PASSWORD},
                headers={"Origin": page.base},
                ssl=trust,
            ) as response:
                assert response.status == 200
                assert "Secure" in response.headers["Set-Cookie"]
            # Plain HTTP to the HTTPS port gets no answer, and the listener goes on.
            with pytest.raises(aiohttp.ClientError):
                async with session.get(f"http://127.0.0.1:{port}/healthz") as response:
                    await response.read()
            async with session.get(f"https://127.0.0.1:{port}/healthz", ssl=trust) as response:
                assert response.status == 200


# -- the configuration --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (
            '[[http.users]]\nname = "a"\npassword_hash = "plain"',
            "http.users[0].password_hash: expected scrypt$N$R$P$SALT$HASH",
        ),
        (
            f'[[http.users]]\nname = "a"\npassword_hash = "{PASSWORD_HASH}"\n'
            f'[[http.users]]\nname = "a"\npassword_hash = "{PASSWORD_HASH}"',
            "http.users[1].name: user 'a' is named twice",
        ),
        (
            '[[http.users]]\nname = "a b"\npassword_hash = "x"',
            "http.users[0].name: expected 1..64 of A-Z a-z 0-9 _ . @ -, got 'a b'",
        ),
        (
            '[[http.tokens]]\nname = "s"\ntoken_hash = "sha256$abc"',
            "http.tokens[0].token_hash: expected sha256$ and 64 hex digits",
        ),
        ('tls_cert = "x.crt"', "http.tls_key: HTTPS needs both tls_cert and tls_key"),
        ('tls_cert = "x.crt"\ntls_key = "x.key"', "http.tls_cert: no such file"),
    ],
)
def test_a_bad_http_section_names_its_key(extra: str, message: str) -> None:
    text = f'[http]\nlisten = "127.0.0.1:0"\n{extra}\n[[lines]]\nurl = "sim://"\nnodes = "1"\n'
    with pytest.raises(GatewayConfigError) as raised:
        parse_config(text, "test.toml")
    assert message in str(raised.value), str(raised.value)


def test_a_certificate_that_does_not_load_starts_nothing(tmp_path: Path) -> None:
    (tmp_path / "x.crt").write_text("not a certificate\n")
    (tmp_path / "x.key").write_text("not a key\n")
    text = (
        f'[http]\nlisten = "127.0.0.1:0"\ntls_cert = "{tmp_path}/x.crt"\n'
        f'tls_key = "{tmp_path}/x.key"\n[[lines]]\nurl = "sim://"\nnodes = "1"\n'
    )
    with pytest.raises(GatewayConfigError, match="cannot load the certificate and key"):
        parse_config(text, "test.toml")


def test_the_command_line_makes_the_hashes() -> None:
    made = subprocess.run(
        [sys.executable, "-m", "sj300_async", "gateway", "--hash-password"],
        input="a long enough password\n", capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert verify_password("a long enough password", made.stdout.strip())
    short = subprocess.run(
        [sys.executable, "-m", "sj300_async", "gateway", "--hash-password"],
        input="short\n", capture_output=True, text=True,
    )  # fmt: skip
    assert short.returncode != 0
    assert short.stderr.count("\n") == 1  # one line, no traceback
    token = subprocess.run(
        [sys.executable, "-m", "sj300_async", "gateway", "--new-token", "report"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    secret = token.stdout.split("not stored): ", 1)[1].split("\n", 1)[0]
    assert f'token_hash = "{hash_token(secret)}"' in token.stdout


# -- parameters -----------------------------------------------------------------------------


def params_config(url: str) -> str:
    """Drives 1-2 may have F002 written (polled, as a grant needs), by alice."""
    text = config_text(url)
    text = text.replace(f"lease_s = {LEASE_S}", f'lease_s = {LEASE_S}\nparameters = ["F002"]')
    return text.replace("control = true", 'control = true\nparameters = ["F002"]')


async def read_all(page: Page, node: int) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The progress events and the backup of a whole-set read over the event stream."""
    progress: list[dict[str, Any]] = []
    url = f"{page.base}/api/v1/drives/hall/{node}/parameters"
    async with page.session.get(url) as response:
        assert response.status == 200
        event = ""
        async for raw in response.content:
            line = raw.decode().rstrip("\n")
            if line.startswith("event: "):
                event = line.removeprefix("event: ")
            elif line.startswith("data: "):
                data = json.loads(line.removeprefix("data: "))
                if event == "progress":
                    progress.append(data)
                elif event == "backup":
                    return progress, data
                else:
                    raise AssertionError(f"{event}: {data}")
    raise AssertionError("the stream ended without a backup")


async def test_a_whole_set_is_read_with_progress_in_the_backup_format(
    sim_line: SimLine,
) -> None:
    async with workbench(params_config(sim_line.url)) as (_, page):
        progress, backup = await read_all(page, 1)
        async with page.session.get(page.base + "/api/v1/drives/hall/1/parameters") as first:
            assert first.status == 200
            await first.content.readline()  # under way
            # One whole set per line at a time: the second waits its turn (409).
            second = page.base + "/api/v1/drives/hall/2/parameters"
            async with page.session.get(second) as refused:
                assert refused.status == 409
                assert "reading a drive's parameters already" in (await refused.json())["error"]
    profile = get_profile("sj300")
    codes = list(profile.parameters.addressable())
    assert [p["done"] for p in progress] == list(range(1, len(codes) + 1))
    assert [p["code"] for p in progress] == codes
    assert backup["format"] == "sj300-params"
    assert backup["node"] == 1
    parsed = ParameterBackup.from_bytes(json.dumps(backup), profile, source="the stream")
    assert parsed.parameters["F002"] == sim_line.sim.drives[1].parameters["F002"]


async def test_a_backup_upload_is_checked_by_the_gateway(sim_line: SimLine) -> None:
    profile = get_profile("sj300")
    backup = ParameterBackup(1, "x", {"F002": 3000}, {"P044": "NAK 16"}).to_json(profile)
    async with workbench(params_config(sim_line.url)) as (_, page):
        url = page.base + "/api/v1/parameters/check?protocol=sj300"
        async with page.session.post(url, data=json.dumps(backup)) as response:
            assert response.status == 200
            checked = await response.json()
        assert checked["parameters"] == {"F002": {"raw": 3000, "value": 30.0}}
        assert checked["absent"] == {"P044": "NAK 16"}

        # A file that arrives in many pieces (an FR-700 backup is about 165 kB) is read
        # whole: a read of what had arrived so far once cut it to its first 16 kB.
        padded = (json.dumps(backup) + " " * 250_000).encode()  # whitespace: still JSON
        assert len(padded) > 200_000

        async def pieces() -> AsyncIterator[bytes]:
            for start in range(0, len(padded), 4096):
                yield padded[start : start + 4096]
                await asyncio.sleep(0)

        async with page.session.post(url, data=pieces()) as response:
            assert response.status == 200, await response.text()
            assert (await response.json())["parameters"] == checked["parameters"]
        bad: list[tuple[bytes, int, str]] = [
            (b"{not json", 400, "the file: not JSON"),
            (b'{"format": "other"}', 400, 'not an sj300-params file: no "format"'),
            (json.dumps(backup | {"protocol": "fr700"}).encode(), 400, "a backup of fr700 drives"),
            (b" " * (1024 * 1024 + 1), 413, "a backup is at most 1024 KiB"),
        ]
        for data, status, message in bad:
            async with page.session.post(url, data=data) as response:
                assert response.status == status
                assert message in (await response.json())["error"]
        other = page.base + "/api/v1/parameters/check?protocol=fr700"
        async with page.session.post(other, data=json.dumps(backup)) as response:
            assert response.status == 400


async def test_a_granted_parameter_is_written_read_back_and_audited(sim_line: SimLine) -> None:
    async with workbench(params_config(sim_line.url)) as (gateway, page):
        assert (await page.post("/api/v1/drives/hall/1/parameter", {"code": "F002"}))[0] == 401
        await page.login()
        await wait_for(
            lambda: "F002" in snapshot_of(gateway, 1).parameters, "F002 polled (the old value)"
        )
        status, answer = await page.control(1, "parameter", code="f002", value=25)
        assert (status, answer["ok"]) == (200, True)
        assert sim_line.sim.drives[1].parameters["F002"] == 2500
        record = gateway.audit.recent[-1]
        assert (record["what"], record["old"], record["new"], record["result"]) == (
            "parameter F002",
            30.0,
            25.0,
            "ok",
        )
        cases: list[tuple[dict[str, Any], int, str]] = [
            ({"code": "F002", "value": 1e6}, 422, "invalid_value"),  # outside its range
            ({"code": "F002", "value": 1.234}, 422, "invalid_value"),  # finer than 0.01 s
            ({"code": "A004", "value": 60}, 403, "not_allowed"),  # not granted
            ({"code": "X999", "value": 1}, 400, "malformed"),
            ({"code": "F002", "raw": "3000"}, 400, "malformed"),
            ({"code": "F002"}, 400, "malformed"),
        ]
        for body, status, refusal in cases:
            got, answer = await page.control(1, "parameter", **body)
            assert (got, answer["refusal"]) == (status, refusal), body
        assert sim_line.sim.drives[1].parameters["F002"] == 2500  # nothing half-applied
        assert (await page.control(3, "parameter", code="F002", value=20))[1]["refusal"] == (
            "not_allowed"
        )


async def test_the_factory_defaults_the_catalogue_knows(sim_line: SimLine) -> None:
    profile = get_profile("sj300")
    async with (
        workbench(params_config(sim_line.url)) as (_, page),
        page.session.get(page.base + "/api/v1/drives/hall/1/defaults") as response,
    ):
        assert response.status == 200
        defaults = await response.json()
    assert defaults["partial"] is True
    assert defaults["parameters"]["F002"] == {"raw": 3000, "value": 30.0}
    known = {
        code
        for code in profile.parameters.addressable()
        if profile.parameters.spec(code).default is not None
    }
    assert set(defaults["parameters"]) == known  # every one the catalogue has, no other
    # The simulated drive starts at its factory settings, but for the frequency and run
    # command sources, which it sets to the RS-485 line (03) so that the line commands it.
    drive = sim_line.sim.drives[1].parameters
    differing = [c for c, d in defaults["parameters"].items() if drive.get(c) != d["raw"]]
    assert differing == ["A001", "A002"]
    assert (drive["A001"], drive["A002"]) == (3, 3)


def _logging_state() -> str:
    """Why a record may not have reached caplog: the HTTP logger's state, the flood limit's."""
    import logging

    from sj300_async.gateway import _logflood

    http = logging.getLogger("sj300_async.gateway.http")
    limit = _logflood.installed()
    return (
        f"level={http.level} effective={http.getEffectiveLevel()} disabled={http.disabled} "
        f"propagate={http.propagate} filters={http.filters!r} users={_logflood._users} "
        f"windows={None if limit is None else len(limit._windows)} "
        f"root={logging.getLogger().level} root_handlers={logging.getLogger().handlers!r} "
        f"disable={logging.root.manager.disable}"
    )
