"""Subscriptions checked against their SUBACK: a refusal is said, counted, and shown on /healthz.

A broker's ACL may refuse one subscription (SUBACK return code 0x80, as
EMQX and HiveMQ answer a denied filter) and accept the connection and every
publish: the client then runs deaf to what that filter carries (the drives'
commands, Home Assistant's birth, a Sparkplug host's STATE, NCMD and DCMD),
and nothing showed it. Every subscription of the JSON bridge and of the
Sparkplug edge node goes through :class:`Subscriptions`; each northbound
exports the counts under its own name (:func:`refused_subscriptions`).

Decisions:

- A refused filter is one WARNING line naming it and what goes unheard,
  when it becomes refused; refused again on the next connections, DEBUG
  (an outage is said once, as :mod:`._session` does); granted again,
  INFO. Every refusal is counted, per topic filter
  (``SessionStats.subscriptions_refused``: a label per filter, bounded by
  the configuration; each filter subscribed is there at 0 before any
  refusal, so a rate sees the first).
- While the broker's last answer for a filter is a refusal, it is one of
  the northbound's :meth:`~Subscriptions.problems` (``/healthz`` says 503
  with it). That answer stands over a lost connection: it is the broker's
  last word, and the ACL rarely changes with a reconnect.
- The connection goes on: what it publishes (states, availability, births)
  still serves, and reconnecting would meet the same ACL, hammering the
  broker for nothing. An operator fixes the ACL; the next connection's
  SUBACK clears the problem.
- Granted at a lower QoS than asked (a broker may) is not a refusal: MQTT
  allows it, and the messages still come.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Final

from ._session import SessionStats
from .client import Client, MqttError

if TYPE_CHECKING:
    from prometheus_client.core import Metric

__all__ = ["REFUSED", "Subscriptions", "refused_subscriptions"]

#: The first SUBACK return code that refuses (MQTT 3.1.1 sends 0x80 only).
REFUSED: Final = 0x80


class Subscriptions:
    """One client's subscriptions, each SUBACK checked (see the module docstring)."""

    def __init__(self, stats: SessionStats, log: logging.Logger, name: str) -> None:
        """*name* starts each log line and problem (``"MQTT"``, ``"Sparkplug"``)."""
        self.stats = stats
        self._log = log
        self._name = name
        #: The filters the broker refused last time, with what goes unheard meanwhile.
        self._refused: dict[str, tuple[int, str]] = {}

    async def subscribe(self, client: Client, topic_filter: str, *, qos: int, unheard: str) -> bool:
        """Subscribe *client* to *topic_filter*; False when the broker refused it.

        Args:
            unheard: what is not received while it is refused, for the log and
                /healthz (``"commands"``).

        Raises:
            MqttError: the connection was lost first.
        """
        counted = self.stats.subscriptions_refused
        counted[topic_filter] += 0  # listed at 0 from the first subscription
        codes = await client.subscribe(topic_filter, qos=qos)
        if len(codes) != 1:
            raise MqttError(
                f"the broker broke MQTT 3.1.1: a SUBACK of {len(codes)} codes for one filter"
            )
        code = codes[0]
        if code < REFUSED:
            if self._refused.pop(topic_filter, None) is not None:
                self._log.info("%s: the broker granted the subscription to %r again",
                               self._name, topic_filter)  # fmt: skip
            return True
        counted[topic_filter] += 1
        again = topic_filter in self._refused
        self._refused[topic_filter] = (code, unheard)
        self._log.log(
            logging.DEBUG if again else logging.WARNING,
            "%s: the broker refused the subscription to %r (SUBACK %#04x): %s not received",
            self._name, topic_filter, code, unheard,
        )  # fmt: skip
        return False

    def problems(self) -> list[str]:
        """Each filter the broker refused at its last SUBACK, one line each."""
        return [
            f"{self._name}: the broker refused the subscription to {topic_filter} "
            f"(SUBACK {code:#04x}): {unheard} not received"
            for topic_filter, (code, unheard) in self._refused.items()
        ]


def refused_subscriptions(name: str, stats: SessionStats) -> Metric:
    """*stats*' refused subscriptions as the counter family *name*, by topic filter."""
    from prometheus_client.core import CounterMetricFamily

    family = CounterMetricFamily(
        name,
        "Subscriptions the broker refused (SUBACK 0x80: an ACL), by topic filter.",
        labels=["filter"],
    )
    for topic_filter, count in stats.subscriptions_refused.items():
        family.add_metric([topic_filter], count)
    return family
