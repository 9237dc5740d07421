"""Reloading the configuration while the gateway runs (SIGHUP, ``systemctl reload``).

A plant changes its configuration while the gateway serves: a user added,
a grant changed, a line added. A restart would drop every Modbus
connection, MQTT and OPC UA session and lease; a reload changes what
changed and nothing else. :func:`plan_reload` compares the running
configuration with the new one (already read and checked: a file that
does not parse changes nothing) and decides, once, what each difference
becomes:

- **A line retuned in place** when only how it is judged or paced
  changed (:data:`RETUNED_FIELDS`: its grants, lease settings, poll
  interval, trip-history and set-frequency intervals). Its bus, poller and
  drives stay; the next request is judged by the new grants; a held lease
  survives unless its drive lost its control grant, and then it lapses at
  once, its drive stopped per ``on_lapse`` (the holder may no longer
  command it, so it must not be left running on its word).
- **A line added** is opened and polled; **a line removed** is stopped
  like the gateway stopping: its held leases lapse (their stops run and
  are waited for), then its poller and bus close. **A line changed
  otherwise** (its URL, protocol, nodes, unit offset, reads, parameters,
  time-out: what its bus, poller or drives' model are made of) is removed
  and added again, so its held leases lapse as on removal: the drives it
  polls may not be the ones the holder commanded. The northbounds are told
  of drives added and removed (:meth:`~._northbound.Northbound` 's
  optional ``drives_changed``).
- **A northbound section added** starts it; **removed** closes it;
  **changed** is handed to the running northbound (its optional
  ``reconfigure``: users, tokens, limits, for the next request) unless
  where it listens changed, which needs a restart.
- **What needs a restart** (:attr:`ReloadPlan.kept`), said in one line
  each and left as it was: the gateway id (every topic and namespace is
  made of it), a northbound's listening address, a northbound that cannot
  take its new section live, the audit log's file.
- ``stale_after_s`` and ``loop_lag_limit_s`` apply from the next sample
  and the next probe.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from ._model import GatewayConfig, LineConfig
from ._northbound import get_northbound

__all__ = ["RETUNED_FIELDS", "ReloadPlan", "plan_reload"]

#: A line's settings a running line takes in place (the module docstring).
RETUNED_FIELDS = frozenset(
    {
        "grants",
        "lease_s",
        "on_lapse",
        "lease_scope",
        "interval_s",
        "trips_interval_s",
        "setpoint_interval_s",
    }
)


@dataclass(frozen=True, slots=True)
class ReloadPlan:
    """What a reload does (the module docstring), decided before anything is touched."""

    #: Lines (their new configuration) taking new settings in place.
    retuned: tuple[LineConfig, ...] = ()
    #: Lines to open and poll, in the new configuration's order.
    added: tuple[LineConfig, ...] = ()
    #: Lines (by name) to stop and close.
    removed: tuple[str, ...] = ()
    #: Lines stopped and opened again with their new configuration.
    replaced: tuple[LineConfig, ...] = ()
    #: Northbound sections to start, to close, and to hand their new configuration.
    started: tuple[str, ...] = ()
    closed: tuple[str, ...] = ()
    reconfigured: tuple[str, ...] = ()
    #: Sections whose new configuration waits for a restart (where they listen changed).
    kept_sections: tuple[str, ...] = ()
    #: The gateway-wide settings that change (``"stale_after_s"``...).
    settings: tuple[str, ...] = ()
    #: What needs a restart and is left as it was, one line each.
    kept: tuple[str, ...] = ()

    @property
    def empty(self) -> bool:
        """Nothing changes (the file is the same, or only in what is kept)."""
        return not any(
            (self.retuned, self.added, self.removed, self.replaced, self.started,
             self.closed, self.reconfigured, self.settings)
        )  # fmt: skip

    def words(self) -> list[str]:
        """What it changes, one phrase each, for the log's one line."""
        out = [f"line {c.name} retuned" for c in self.retuned]
        out += [f"line {c.name} added" for c in self.added]
        out += [f"line {name} removed" for name in self.removed]
        out += [f"line {c.name} replaced" for c in self.replaced]
        out += [f"[{s}] started" for s in self.started]
        out += [f"[{s}] closed" for s in self.closed]
        out += [f"[{s}] reconfigured" for s in self.reconfigured]
        out += [f"{name} changed" for name in self.settings]
        return out


def plan_reload(old: GatewayConfig, new: GatewayConfig) -> ReloadPlan:
    """What reloading *new* over the running *old* does (the module docstring)."""
    kept: list[str] = []
    if new.gateway_id != old.gateway_id:
        kept.append(
            f"gateway.id: {old.gateway_id!r} until a restart (every topic and namespace is "
            f"made of it; the file says {new.gateway_id!r})"
        )
    if new.audit_log != old.audit_log:
        kept.append(f"gateway.audit_log: {old.audit_log} until a restart")
    if new.recorder != old.recorder:  # the trends it sized, the records pending: its own
        kept.append("recorder: as it was until a restart")
    settings = tuple(
        name
        for name in ("stale_after_s", "loop_lag_limit_s")
        if getattr(new, name) != getattr(old, name)
    )
    retuned: list[LineConfig] = []
    added: list[LineConfig] = []
    replaced: list[LineConfig] = []
    before = {line.name: line for line in old.lines}
    for line in new.lines:
        was = before.get(line.name)
        if was is None:
            added.append(line)
        elif was != line:
            differ = {name for name in _names(line) if getattr(line, name) != getattr(was, name)}
            (retuned if differ <= RETUNED_FIELDS else replaced).append(line)
    names = {line.name for line in new.lines}
    removed = tuple(line.name for line in old.lines if line.name not in names)
    started, closed, reconfigured, kept_sections = _sections(old.northbounds, new.northbounds, kept)
    return ReloadPlan(
        retuned=tuple(retuned),
        added=tuple(added),
        removed=removed,
        replaced=tuple(replaced),
        started=started,
        closed=closed,
        reconfigured=reconfigured,
        kept_sections=kept_sections,
        settings=settings,
        kept=tuple(kept),
    )


def _names(line: LineConfig) -> list[str]:
    return [f.name for f in dataclasses.fields(line)]


def _sections(
    old: Mapping[str, object], new: Mapping[str, object], kept: list[str]
) -> tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...], tuple[str, ...]]:
    started = tuple(section for section in new if section not in old)
    closed = tuple(section for section in old if section not in new)
    reconfigured, waiting = [], []
    for section, settings in new.items():
        if section not in old or old[section] == settings:
            continue
        spec = get_northbound(section)
        was = _listening(spec.endpoints(old[section]))
        now = _listening(spec.endpoints(settings))
        if was != now:
            kept.append(
                f"{section}: listens on {', '.join(was) or 'nothing'} until a restart "
                f"(the file says {', '.join(now) or 'nothing'}); the rest of [{section}] too"
            )
            waiting.append(section)
            continue
        reconfigured.append(section)
    return started, closed, tuple(reconfigured), tuple(waiting)


def _listening(endpoints: Sequence[tuple[str, object]]) -> list[str]:
    return [f"{key} {endpoint}" for key, endpoint in endpoints]
