"""A real Home Assistant of a test's own: configured without its UI, started, asked, stopped.

``make test-ha`` installs Home Assistant from PyPI into a venv of its own on
a Python it supports (3.13), with every requirement of the integrations the
tests load (``requirements.py``), and runs the tests with ``--home-assistant
PATH`` (its ``hass``). Here:

- the configuration directory is written as an installer's would be,
  without the UI: ``configuration.yaml`` (HTTP on a free loopback port, the
  recorder, the logbook) and ``.storage/core.config_entries`` holding the
  MQTT integration's entry for the test's mosquitto, discovery on;
- ``hass --skip-pip`` starts on it, so a run installs nothing and needs no
  network; :meth:`HomeAssistant.start` returns once its HTTP API answers;
- :meth:`HomeAssistant.onboard` creates the owner as HA's onboarding page
  would (its onboarding API), and keeps the access token, which outlives a
  restart (HA signs it with a key in ``.storage/auth``);
- :class:`HassSocket` is HA's websocket API: service calls, states, the
  registries, as HA's own frontend asks;
- after :meth:`HomeAssistant.stop` (SIGTERM: HA saves its ``.storage`` files
  on the way out), :meth:`storage` reads them and :meth:`recorded` the
  recorder's SQLite database.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import sqlite3
import textwrap
import uuid
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import aiohttp
from mqtt_broker import free_port, stop_process

__all__ = ["HassSocket", "HomeAssistant"]

#: How long HA may take to start or stop (a cold start loads every integration's code).
START_S = 120.0
STOP_S = 60.0
USER = "operator"
PASSWORD = "sj300-test-password"


def _config_entry(broker_port: int) -> dict[str, Any]:
    """The MQTT integration's entry as HA's config flow stores it (its version 1.2)."""
    now = datetime.now(UTC).isoformat()
    return {
        "created_at": now,
        "data": {"broker": "127.0.0.1", "port": broker_port},
        "discovery_keys": {},
        "disabled_by": None,
        "domain": "mqtt",
        "entry_id": uuid.uuid4().hex,
        "minor_version": 2,
        "modified_at": now,
        "options": {"discovery": True, "discovery_prefix": "homeassistant"},
        "pref_disable_new_entities": False,
        "pref_disable_polling": False,
        "source": "user",
        "subentries": [],
        "title": "127.0.0.1",
        "unique_id": None,
        "version": 1,
    }


@dataclass
class HomeAssistant:
    """One Home Assistant, its configuration in *directory*, on the broker at *broker_port*."""

    hass: Path
    directory: Path
    broker_port: int
    port: int = field(default_factory=free_port)
    token: str = ""
    refresh_token: str = ""
    proc: asyncio.subprocess.Process | None = None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def client_id(self) -> str:
        """What HA's frontend calls itself (its origin), so the tokens serve it too."""
        return f"{self.url}/"

    def configure(self) -> None:
        """Write configuration.yaml and the MQTT integration's config entry."""
        self.directory.mkdir(parents=True, exist_ok=True)
        (self.directory / "configuration.yaml").write_text(
            textwrap.dedent(
                f"""\
                homeassistant:
                  name: sj300 test plant
                  time_zone: UTC
                  unit_system: metric
                  country: DE
                  currency: EUR
                  latitude: 0
                  longitude: 0
                  elevation: 0
                  internal_url: {self.url}
                http:
                  server_host: 127.0.0.1
                  server_port: {self.port}
                recorder:
                  commit_interval: 1
                logbook:
                history:
                logger:
                  default: warning
                """
            ),
            encoding="utf-8",
        )
        storage = self.directory / ".storage"
        storage.mkdir(exist_ok=True)
        entries = {
            "version": 1,
            "minor_version": 5,
            "key": "core.config_entries",
            "data": {"entries": [_config_entry(self.broker_port)]},
        }
        (storage / "core.config_entries").write_text(json.dumps(entries), encoding="utf-8")

    async def start(self) -> None:
        """Start ``hass``; return once its HTTP API answers (onboarding's, before it).

        A start that fails leaves no ``hass`` behind: it is stopped before the failure
        is raised (one left running once kept the CPU of later runs).
        """
        try:
            await self._start()
        except BaseException:
            proc, self.proc = self.proc, None
            if proc is not None:
                await stop_process(proc, grace_s=STOP_S)
            raise

    async def _start(self) -> None:
        assert self.proc is None
        output = (self.directory / "hass.out").open("ab")
        try:
            self.proc = await asyncio.create_subprocess_exec(
                str(self.hass),
                "--config",
                str(self.directory),
                "--skip-pip",
                stdout=output,
                stderr=asyncio.subprocess.STDOUT,
            )
        finally:
            output.close()
        loop = asyncio.get_running_loop()
        deadline = loop.time() + START_S
        # Onboarding's API is there until it is done; then the API answers the owner.
        probe, headers = f"{self.url}/api/onboarding", {}
        if self.token:
            probe, headers = f"{self.url}/api/", {"Authorization": f"Bearer {self.token}"}
        async with aiohttp.ClientSession() as session:
            while True:
                if self.proc.returncode is not None:
                    raise AssertionError(f"hass exited with {self.proc.returncode}: {self.tail()}")
                with contextlib.suppress(aiohttp.ClientError, OSError):
                    async with session.get(probe, headers=headers) as response:
                        if response.status == 200:
                            return
                if loop.time() > deadline:
                    raise AssertionError(f"hass did not answer in {START_S} s: {self.tail()}")
                await asyncio.sleep(0.2)

    async def stop(self) -> None:
        """SIGTERM, as systemd stops it: HA saves its storage and closes its recorder."""
        proc, self.proc = self.proc, None
        if proc is not None:
            await stop_process(proc, grace_s=STOP_S)
            assert proc.returncode == 0, f"hass exited with {proc.returncode}: {self.tail()}"

    async def onboard(self) -> None:
        """Create the owner through HA's onboarding API and finish its steps; keep a token."""
        async with aiohttp.ClientSession() as session:
            owner = {
                "client_id": self.client_id,
                "name": "Operator",
                "username": USER,
                "password": PASSWORD,
                "language": "en",
            }
            async with session.post(f"{self.url}/api/onboarding/users", json=owner) as r:
                assert r.status == 200, await r.text()
                code = (await r.json())["auth_code"]
            form = {"grant_type": "authorization_code", "code": code, "client_id": self.client_id}
            async with session.post(f"{self.url}/auth/token", data=form) as r:
                assert r.status == 200, await r.text()
                tokens = await r.json()
            self.token, self.refresh_token = tokens["access_token"], tokens["refresh_token"]
            headers = {"Authorization": f"Bearer {self.token}"}
            steps = [
                ("core_config", {}),
                ("analytics", {}),
                ("integration", {"client_id": self.client_id, "redirect_uri": self.url}),
            ]
            for step, body in steps:
                url = f"{self.url}/api/onboarding/{step}"
                async with session.post(url, json=body, headers=headers) as r:
                    assert r.status == 200, (step, await r.text())
            # The integrations onboarding set up on its own (a weather service, text to
            # speech...) need the internet: removed, as a user without it would.
            entries_url = f"{self.url}/api/config/config_entries/entry"
            async with session.get(entries_url, headers=headers) as r:
                entries = await r.json()
            for entry in entries:
                if entry["domain"] != "mqtt":
                    url = f"{entries_url}/{entry['entry_id']}"
                    async with session.delete(url, headers=headers) as r:
                        assert r.status == 200, (entry["domain"], await r.text())

    @contextlib.asynccontextmanager
    async def socket(self) -> AsyncIterator[HassSocket]:
        """HA's websocket API, authenticated with the owner's token."""
        async with (
            aiohttp.ClientSession() as session,
            session.ws_connect(f"{self.url}/api/websocket") as ws,
        ):
            assert (await ws.receive_json())["type"] == "auth_required"
            await ws.send_json({"type": "auth", "access_token": self.token})
            reply = await ws.receive_json()
            assert reply["type"] == "auth_ok", reply
            yield HassSocket(ws)

    def storage(self, key: str) -> Any:
        """The ``data`` of ``.storage/<key>`` (read after :meth:`stop`, which saves it)."""
        return json.loads((self.directory / ".storage" / key).read_text(encoding="utf-8"))["data"]

    def recorded(self, sql: str, *args: object) -> list[tuple[Any, ...]]:
        """Rows of the recorder's database (read after :meth:`stop`, which commits it)."""
        with contextlib.closing(sqlite3.connect(self.directory / "home-assistant_v2.db")) as db:
            return db.execute(sql, args).fetchall()

    def log(self) -> list[str]:
        """HA's log, line by line: the last run's and the one before (HA renames it at a
        start, to ``home-assistant.log.1``)."""
        lines: list[str] = []
        for name in ("home-assistant.log.1", "home-assistant.log"):
            path = self.directory / name
            if path.exists():
                lines += path.read_text(encoding="utf-8", errors="replace").splitlines()
        return lines

    def tail(self, lines: int = 30) -> str:
        path = self.directory / "hass.out"
        text = path.read_text(encoding="utf-8", errors="replace") if path.exists() else ""
        return "\n".join(text.splitlines()[-lines:])


@dataclass
class HassSocket:
    """One authenticated websocket connection to HA: commands and their results."""

    ws: aiohttp.ClientWebSocketResponse
    next_id: int = 1

    async def ask(self, kind: str, **fields: object) -> Any:
        """Send command *kind*; return its result (failing the test on an error)."""
        ask_id, self.next_id = self.next_id, self.next_id + 1
        await self.ws.send_json({"id": ask_id, "type": kind, **fields})
        while True:
            reply = await asyncio.wait_for(self.ws.receive_json(), 30)
            if reply.get("id") == ask_id and reply.get("type") == "result":
                assert reply["success"], (kind, fields, reply.get("error"))
                return reply["result"]

    async def states(self) -> dict[str, dict[str, Any]]:
        """Every entity's state now, by entity id."""
        return {s["entity_id"]: s for s in await self.ask("get_states")}

    async def call(self, domain: str, service: str, entity_id: str, **data: object) -> None:
        """A service call, as an automation or a dashboard makes it."""
        await self.ask(
            "call_service",
            domain=domain,
            service=service,
            target={"entity_id": entity_id},
            service_data=data,
        )
