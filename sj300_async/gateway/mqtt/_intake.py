"""The command intake's budgets: a flood on the command topics costs a lookup per message.

Anyone the broker lets publish to ``…/set/#`` can send the gateway
thousands of messages a second. Each one the bridge judged cost a parse,
an audit record and an error reply (JSON, published at QoS 1): 200-220 µs
of the event loop a message of issue 41's junk mix, 56-70 µs dropped
here (what is left is reading its bytes), and without a budget about 900
error publishes a second back through the broker. So the bridge spends
from :class:`CommandIntake` before it reads a command's payload, and
before it publishes a refusal:

- **Commands, per drive and in all** (:data:`COMMAND_BUDGET`): past either, a
  command is dropped unread, counted (``result="throttled"``), with no
  reply and no audit record (that would be the flood again). Per drive,
  so that junk aimed at one drive leaves the others' commands through; in
  all, so that junk spread over every drive's topics is bounded too (a
  plant has up to 2,048 drives). Spent per drive first: a drive's own
  flood is refused there without using up the common budget.
- **Stops have budgets of their own**, the same size: junk never uses up
  a stop's. A flood of stops only stops the motor, which one stop does.
- **Error replies** (:data:`REPLY_BUDGET`): past the budget, a refusal is still
  counted and audited, but not answered on ``…/error`` (counted in
  ``errors_dropped``).
- **Generous defaults.** A person or Home Assistant sends a few commands a
  second, a SCADA a heartbeat per drive every second or so: 20 at once and
  10 a second per drive, 200 and 100 a second in all, never reached by
  them. 100 commands a second judged cost the loop about 1.5% of its time
  (docs/GATEWAY.md, "Commands").
- **One line, not one per drop**: a WARNING when the first is dropped,
  then at most one every :data:`SAY_EVERY_S` saying how many since.

Time is the caller's clock (``time.monotonic``), so the tests drive it.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Final

from .. import KeyedBudget

__all__ = ["COMMAND_BUDGET", "REPLY_BUDGET", "SAY_EVERY_S", "Budget", "CommandIntake"]

#: At most one "commands dropped" line this often.
SAY_EVERY_S: Final = 10.0
_ALL: Final = "all"


@dataclass(frozen=True, slots=True)
class Budget:
    """Token buckets: *burst* at once and *per_s* a second, per drive and in all."""

    burst: int
    per_s: int
    all_burst: int
    all_per_s: int

    def __str__(self) -> str:
        return (
            f"{self.burst} at once and {self.per_s}/s per drive, "
            f"{self.all_burst} and {self.all_per_s}/s in all"
        )


#: Commands taken (stops: the same again, apart).
COMMAND_BUDGET: Final = Budget(burst=20, per_s=10, all_burst=200, all_per_s=100)
#: Error replies published.
REPLY_BUDGET: Final = Budget(burst=10, per_s=2, all_burst=50, all_per_s=20)


class _TwoLevel:
    """A budget per key and one for every key together (spent per key first)."""

    __slots__ = ("_all", "_each")

    def __init__(self, budget: Budget, clock: Callable[[], float]) -> None:
        self._each = KeyedBudget(budget.burst, budget.per_s, clock=clock)
        self._all = KeyedBudget(budget.all_burst, budget.all_per_s, max_keys=4, clock=clock)

    def retune(self, budget: Budget) -> None:
        """*budget*'s rates from now on; what each key spent is kept."""
        self._each.burst, self._each.per_s = float(budget.burst), float(budget.per_s)
        self._all.burst, self._all.per_s = float(budget.all_burst), float(budget.all_per_s)

    def spend(self, key: Hashable, group: Hashable = _ALL) -> bool:
        if not self._each.spend(key):
            return False
        if self._all.spend(group):
            return True
        self._each.refund(key)  # refused in all: the drive's own budget was not the reason
        return False


class CommandIntake:
    """What the bridge may take and answer now (see the module docstring)."""

    def __init__(
        self,
        log: logging.Logger,
        *,
        commands: Budget = COMMAND_BUDGET,
        replies: Budget = REPLY_BUDGET,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._log = log
        self._clock = clock
        self.commands = commands
        self._commands = _TwoLevel(commands, clock)
        self._replies = _TwoLevel(replies, clock)
        self._said_at = -SAY_EVERY_S
        #: Drops not said yet, and when the first of them was.
        self._unsaid = 0
        self._since = 0.0

    def retune(self, commands: Budget) -> None:
        """The commands' budget of a reload, from the next command."""
        self.commands = commands
        self._commands.retune(commands)

    def admit(self, drive: tuple[str, int], *, stop: bool, topic: Callable[[], str]) -> bool:
        """Spend a command of *drive*; False (one line now and then): drop it unread.

        Args:
            topic: the command's topic as a log shows it (made only to be said).
        """
        if stop:
            allowed = self._commands.spend(("stop", drive), "stop")
        else:
            allowed = self._commands.spend(drive)
        if allowed:
            return True
        now = self._clock()
        if not self._unsaid:
            self._since = now
        self._unsaid += 1
        if now - self._said_at < SAY_EVERY_S:
            return False
        if self._unsaid == 1:
            self._log.warning(
                "MQTT: a command on %s dropped unread, past the intake budget (%s): no reply, "
                "no audit; those that follow are counted and said at most every %g s",
                topic(), self.commands, SAY_EVERY_S,
            )  # fmt: skip
        else:
            self._log.warning(
                "MQTT: %d commands dropped unread in %.0f s, past the intake budget (%s); "
                "the last on %s",
                self._unsaid, now - self._since, self.commands, topic(),
            )  # fmt: skip
        self._said_at, self._unsaid = now, 0
        return False

    def reply(self, drive: tuple[str, int]) -> bool:
        """Spend an error reply to *drive*'s command: False, it is not published."""
        return self._replies.spend(drive)
