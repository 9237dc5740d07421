"""Carrying out a reload on the running gateway (what changes is :mod:`._reload`'s).

:func:`reload_file` is what SIGHUP runs (``sj300 gateway``, ``systemctl
reload``): the file read as a start reads it, then checked as
``--check-config`` checks it for what this reload would start (a new
section's libraries, ports and files): a file that fails either changes
nothing, said in one log line and counted
(``sj300_gateway_config_reloads_total{result="refused"}``,
``sj300_gateway_config_last_reload_successful`` 0). Then
:func:`apply_reload` opens the new lines' buses first (a line whose bus can
never open, as a start would refuse it, refuses the reload before anything
changed), and changes, in this order: the gateway-wide settings; the
retuned lines; the lines removed or replaced (out of the gateway's maps, the
northbounds told, then their leases lapse and they close); the lines added
(opened, the northbounds told, then polled); the northbound sections closed,
reconfigured and started. Each step's failure is its own: logged, said in
the reload's outcome, and the next step goes on (a line whose device is
down now is opened down, served offline and retried, as at a start).

This module is the gateway's friend: it reaches the :class:`~._gateway.Gateway`'s
line and northbound primitives (``_open_buses``, ``_stop_line``...), which
exist for it and for the gateway's own start and stop.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import importlib.util
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ._check import probe_endpoint
from ._errors import GatewayStartError
from ._model import GatewayConfig, LineConfig
from ._northbound import get_northbound
from ._reload import ReloadPlan, plan_reload
from ._toml import GatewayConfigError

if TYPE_CHECKING:
    from ..bus import Bus
    from ._gateway import Gateway, GatewayLine

__all__ = ["ReloadOutcome", "apply_reload", "reload_file"]

_log = logging.getLogger("sj300_async.gateway")


@dataclass(frozen=True, slots=True)
class ReloadOutcome:
    """What a reload did: refused (nothing changed), or its plan and what was left."""

    #: None: the file was refused (:attr:`refusal` says why); else what was planned.
    plan: ReloadPlan | None
    #: Why the file changed nothing (the start's one line), "" when it was taken.
    refusal: str = ""
    #: What needs a restart, and what failed on the way, one line each.
    notes: tuple[str, ...] = ()

    @property
    def refused(self) -> bool:
        return self.plan is None


async def reload_file(gateway: Gateway, path: str | os.PathLike[str]) -> ReloadOutcome:
    """Read *path*, check it, and apply it to *gateway* (see the module docstring)."""
    from ._config import load_config

    try:
        config = await asyncio.to_thread(load_config, path)  # a big file: off the loop
        plan = plan_reload(gateway.config, config)
    except GatewayConfigError as exc:
        return _refused(gateway, str(exc))
    return await apply_reload(gateway, config, plan)


def _refused(gateway: Gateway, why: str) -> ReloadOutcome:
    gateway.reloads["refused"] += 1
    gateway.last_reload_ok = False
    _log.error("reload refused, still running the configuration it had: %s", why)
    return ReloadOutcome(None, refusal=why)


def _check_started(config: GatewayConfig, plan: ReloadPlan) -> None:
    """What the sections this reload starts need, checked as ``--check-config`` does.

    Raises:
        GatewayStartError: a library missing, a port not free, a file that does not load.
    """
    for section in plan.started:
        settings = config.northbounds[section]
        spec = get_northbound(section)
        for module in spec.requires:
            if importlib.util.find_spec(module) is None:
                raise GatewayStartError(section, (), f"{module} is not installed")
        for _, endpoint in spec.endpoints(settings):
            try:
                probe_endpoint(endpoint)
            except OSError as exc:
                raise GatewayStartError.of(section, [endpoint], exc) from None
        check = getattr(spec, "check", None)
        if check is not None:
            check(settings)


async def apply_reload(
    gateway: Gateway, config: GatewayConfig, plan: ReloadPlan | None = None
) -> ReloadOutcome:
    """Change the running *gateway* to *config* (checked), as *plan* says (module docstring)."""
    old = gateway.config
    try:  # here, not in reload_file: Gateway.reload(config) is checked the same
        if plan is None:
            plan = plan_reload(old, config)
        _check_started(config, plan)
    except (GatewayConfigError, GatewayStartError) as exc:
        return _refused(gateway, str(exc))
    coming = [*plan.added, *plan.replaced]
    try:  # first: a line whose bus can never open refuses the reload before any change
        buses = await gateway._open_buses(coming) if coming else []
    except Exception as exc:  # what open_bus raises for a URL that cannot work: a start's
        return _refused(gateway, f"a line cannot be opened: {exc}")
    notes = list(plan.kept)
    _settings(gateway, config)
    for line_config in plan.retuned:
        line = _line(gateway, line_config.name)
        line.config = line_config
        line.poller.interval_s = line_config.interval_s
        line.controller.retune(line_config, line.drives.values())
    names = [*plan.removed, *(c.name for c in plan.replaced)]
    going = [_line(gateway, name) for name in names]
    # The merged configuration: what is kept stays as it was, the rest is the file's.
    sections = {
        section: old.northbounds[section] if section in plan.kept_sections else settings
        for section, settings in config.northbounds.items()
    }
    gateway.config = dataclasses.replace(
        config,
        northbounds=sections,
        gateway_id=old.gateway_id,
        audit_log=old.audit_log,
        recorder=old.recorder,
    )
    await _swap_lines(gateway, going, coming, buses, notes)
    await _northbound_sections(gateway, plan, notes)
    _order(gateway)
    gateway.reloads["applied"] += 1
    gateway.last_reload_ok = True
    words = plan.words() or ["nothing changed"]
    _log.info("reloaded: %s%s", ", ".join(words), "".join(f"; {note}" for note in notes))
    return ReloadOutcome(plan, notes=tuple(notes))


def _settings(gateway: Gateway, config: GatewayConfig) -> None:
    gateway.loop_monitor.limit_s = config.loop_lag_limit_s
    for drive in gateway.drives:
        drive.stale_after_s = config.stale_after_s  # from its next snapshot


def _line(gateway: Gateway, name: str) -> GatewayLine:
    return next(line for line in gateway.lines if line.config.name == name)


async def _swap_lines(
    gateway: Gateway,
    going: Sequence[GatewayLine],
    coming: Sequence[LineConfig],
    buses: Sequence[tuple[Bus[Any, Any], contextlib.AsyncExitStack]],
    notes: list[str],
) -> None:
    """Remove *going* and add lines of *coming* on their opened *buses* (a replaced line
    is both)."""
    for line in going:
        gateway.lines.remove(line)
        for drive in line.drives.values():
            gateway._forget_drive(drive)
    gateway._batch.flush()  # what was gathered before, out now: nothing of them after
    pairs = zip(coming, buses, strict=True)
    added = [gateway._open_line(c, bus, stack) for c, (bus, stack) in pairs]
    gateway.lines.extend(added)
    if going or added:
        await _tell_northbounds(gateway, added, going, notes)
    # Their leases lapse (stops sent and waited for, as on the gateway's stop), together.
    await asyncio.gather(*(gateway._stop_line(line) for line in going))
    for line in added:
        await gateway._start_line(line)


async def _tell_northbounds(
    gateway: Gateway, added: Sequence[GatewayLine], removed: Sequence[GatewayLine], notes: list[str]
) -> None:
    for section, northbound in list(gateway.northbounds.items()):
        hook = getattr(northbound, "lines_changed", None)
        if hook is not None:
            try:
                await hook(added, removed)
                continue
            except Exception:
                _log.exception("the %s northbound failed to take the lines' change", section)
        notes.append(f"[{section}] restarted to serve the changed lines (its clients reconnect)")
        await _restart(gateway, section, gateway.config.northbounds[section], notes)


async def _restart(gateway: Gateway, section: str, settings: object, notes: list[str]) -> None:
    await _close(gateway, section, notes)
    await _start(gateway, section, settings, notes)


async def _close(gateway: Gateway, section: str, notes: list[str]) -> None:
    northbound = gateway.northbounds.pop(section)
    try:
        await northbound.close()
    except Exception:
        _log.exception("the %s northbound failed to close", section)
        notes.append(f"[{section}] failed to close (logged)")


async def _start(gateway: Gateway, section: str, settings: object, notes: list[str]) -> None:
    try:
        await gateway._start_northbound(section, settings)
    except Exception as exc:  # a start's error: said, and served by /healthz
        why = str(exc) or type(exc).__name__
        gateway.northbound_failures[section] = why
        _log.error("reload: [%s] did not start: %s", section, why)
        notes.append(f"[{section}] did not start: {why}")
    else:
        gateway.northbound_failures.pop(section, None)


async def _northbound_sections(gateway: Gateway, plan: ReloadPlan, notes: list[str]) -> None:
    for section in plan.closed:
        await _close(gateway, section, notes)
    for section in plan.reconfigured:
        northbound = gateway.northbounds.get(section)
        settings = gateway.config.northbounds[section]
        if northbound is None:  # it failed to start before: try again
            await _start(gateway, section, settings, notes)
            continue
        hook: Any = getattr(northbound, "reconfigure", None)
        kept = ["every key"] if hook is None else list(hook(settings))
        if kept:
            notes.append(f"[{section}] {', '.join(kept)}: as it was until a restart")
    for section in plan.started:
        await _start(gateway, section, gateway.config.northbounds[section], notes)


def _order(gateway: Gateway) -> None:
    """Lines, drives and northbounds in the configuration's order again."""
    rank = {line.name: index for index, line in enumerate(gateway.config.lines)}
    gateway.lines.sort(key=lambda line: rank[line.config.name])
    gateway._reorder_drives()
    order = list(gateway.config.northbounds)
    running = dict(gateway.northbounds)
    gateway.northbounds.clear()
    for section in sorted(running, key=lambda s: order.index(s) if s in order else len(order)):
        gateway.northbounds[section] = running[section]
