"""The control lease kept by Home Assistant's presence: no heartbeat automation to write.

A drive runs only under a control lease that lapses (and stops it) unless
renewed every ``lease_s``; with plain MQTT, the user had to write an
automation pressing the heartbeat button, or Run did nothing after the
lease ran out (issue 43). With ``[mqtt] home_assistant_lease = true`` (the
default) the bridge renews the lease itself for as long as Home Assistant
is there, as its own MQTT presence says:

- **Present** once ``homeassistant/status`` said ``online`` (its birth,
  retained or not) and not ``offline`` since (its last will, or a clean
  stop). Before either, nothing is known: leases are plain.
- While present, a command from MQTT to run or set a frequency takes the
  lease first when nobody holds it (no "take the control lease first"
  refusal), and every drive whose lease an MQTT command took or renewed
  while present is renewed by the bridge every ``lease_s / 2`` (a
  heartbeat through the controller, audited as any).
- **Its end is the lapse.** Home Assistant's ``offline`` and its next
  birth (a restart: its automations start over) end the renewals: each
  such lease lapses within its ``lease_s`` and the line's ``on_lapse``
  stops the motor. So does the bridge losing the broker (no renewals
  without a connection).

The safety argument, and what it rests on (docs/GATEWAY.md): Home
Assistant gone is noticed by its last will, which the broker sends at once
when its connection closes and 1.5 keepalives after it went silent (60 s
by default: set HA's MQTT keepalive short where that matters); anyone
the broker lets publish on ``homeassistant/status`` can say ``online``,
as anyone it lets publish on the command topics can run a drive. A
client that is not Home Assistant keeps its plain lease: the heartbeat
button stays.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Iterator
from typing import TYPE_CHECKING, Final

from .. import Heartbeat, WriteRequest, needs_lease

if TYPE_CHECKING:
    from prometheus_client import Metric

    from .. import GatewayDrive, GatewayView

__all__ = ["RENEW_EVERY_S", "HomeAssistantLease"]

_log = logging.getLogger("sj300_async.gateway.mqtt")

#: How often the renewals are looked at (each lease is renewed at half its time).
RENEW_EVERY_S: Final = 0.25
_ONLINE, _OFFLINE = b"online", b"offline"


class HomeAssistantLease:
    """The leases Home Assistant's presence keeps (see the module docstring)."""

    def __init__(self, client: str, *, enabled: bool) -> None:
        self._client = client
        self.enabled = enabled
        #: Home Assistant's presence: None before it said anything.
        self.present: bool | None = None
        #: The drives whose lease the bridge renews while Home Assistant is present.
        self._kept: set[tuple[str, int]] = set()
        #: What Home Assistant said (and connections lost), counted: a command keeps its
        #: lease only under the presence it began under (:meth:`before`, :meth:`after`).
        self._heard = 0
        self._began: dict[tuple[str, int], int] = {}

    def heard(self, payload: bytes) -> None:
        """Home Assistant said *payload* on its status topic (a birth, its will)."""
        said = payload.strip()
        if said not in (_ONLINE, _OFFLINE):
            return
        self._heard += 1
        if self._kept:
            # Its birth (a restart) or its end: the leases it kept lapse now on their own.
            _log.info("MQTT: Home Assistant said %s: the leases it kept (%d) are left to lapse",
                      said.decode(), len(self._kept))  # fmt: skip
            self._kept.clear()
        self.present = said == _ONLINE

    async def before(
        self,
        gateway: GatewayView,
        drive: GatewayDrive,
        request: WriteRequest,
        connection: str | None,
    ) -> None:
        """A command from MQTT is about to go through: while Home Assistant is present, take
        the free lease for a command that needs it."""
        self._began[drive.key] = self._heard
        if not (self.enabled and self.present) or not needs_lease(request):
            return
        now = asyncio.get_running_loop().time()
        if not drive.lease.held(now):
            await gateway.write(self._client, drive, Heartbeat(), connection=connection)

    def after(self, drive: GatewayDrive, request: WriteRequest) -> None:
        """A command from MQTT went through: while Home Assistant is present, the lease it
        took or renewed is kept (a stop keeps nothing new). Not when Home Assistant said
        anything since :meth:`before`: its birth during the write (a restart) or its will
        ended the renewals, the lease this command took with them."""
        began = self._began.pop(drive.key, None)
        if not (self.enabled and self.present) or began != self._heard:
            return
        now = asyncio.get_running_loop().time()
        if drive.lease.held_by(self._client, now) and (
            isinstance(request, Heartbeat) or needs_lease(request)
        ):
            self._kept.add(drive.key)

    async def keep(self, gateway: GatewayView, connection: str | None) -> None:
        """Renew the kept leases at half their time, while the connection lasts (a task)."""
        while True:
            await asyncio.sleep(RENEW_EVERY_S)
            if not self.present:
                continue
            now = asyncio.get_running_loop().time()
            for key in list(self._kept):
                drive = gateway.drive(*key)
                lease = None if drive is None else drive.lease
                if drive is None or lease is None or not lease.held_by(self._client, now):
                    self._kept.discard(key)  # lapsed, taken over or released: not ours
                elif lease.seconds_left(now) < lease.duration_s / 2:
                    await gateway.write(self._client, drive, Heartbeat(), connection=connection)

    def metrics(self) -> Iterator[Metric]:
        """Whether Home Assistant is present as the bridge sees it, and the leases it keeps:
        what a user checks when a run from Home Assistant is refused ``no_lease``."""
        from prometheus_client.core import GaugeMetricFamily

        present = GaugeMetricFamily(
            "sj300_mqtt_home_assistant_present",
            "1 while Home Assistant's birth said online and nothing since said offline; 0 "
            "before it said anything, after its will, and without the broker.",
        )
        present.add_metric([], 1.0 if self.enabled and self.present else 0.0)
        yield present
        kept = GaugeMetricFamily(
            "sj300_mqtt_home_assistant_leases",
            "Drives whose control lease the gateway renews while Home Assistant is present.",
        )
        kept.add_metric([], float(len(self._kept)))
        yield kept

    def lost(self) -> None:
        """The broker connection ended: no renewals without it (the leases lapse), and
        Home Assistant's presence unknown until it is heard again (a retained birth)."""
        self._kept.clear()
        self._heard += 1
        self.present = None
