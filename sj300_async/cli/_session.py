"""How ``sj300 shell`` lends its event loop and its bus to the commands it runs.

On the command line each subcommand runs its coroutine with
:func:`asyncio.run` and opens a bus of its own with
:func:`~._common.open_cli_bus`. In the shell one bus stays open for the
whole session (a ``sim://`` bus keeps its drives' state from one command to
the next), in one event loop, held by an :class:`asyncio.Runner`:

- :func:`run_async` is what a subcommand's ``run(args)`` calls instead of
  :func:`asyncio.run`: outside the shell it *is* asyncio.run; inside, it
  runs the coroutine in the shell's loop (Ctrl-C interrupts that command
  the same way, as KeyboardInterrupt);
- :func:`lent_bus` is what :func:`~._common.open_cli_bus` yields instead of
  opening a bus, when the shell lends one to the command running now (it
  does not close it).

Both are context variables the shell sets (:func:`lending`) around each
command, so nothing leaks to code running outside it. A subcommand still
calling asyncio.run works in the shell too, with a bus of its own: the
lent bus is only handed out in the loop it lives in.
"""

from __future__ import annotations

import asyncio
import contextvars
from collections.abc import Coroutine, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

from ..bus import Bus

__all__ = ["lending", "lent_bus", "run_async"]

_T = TypeVar("_T")

#: The shell's runner, while a shell command runs.
_shell_runner: contextvars.ContextVar[asyncio.Runner | None] = contextvars.ContextVar(
    "sj300_shell_runner", default=None
)
#: The bus the shell lends the command running now (None: the command opens its own).
_shared_bus: contextvars.ContextVar[Bus | None] = contextvars.ContextVar(
    "sj300_shared_bus", default=None
)


def run_async(main: Coroutine[Any, Any, _T]) -> _T:
    """Run a subcommand's coroutine: :func:`asyncio.run`, or in the shell's loop in a shell."""
    runner = _shell_runner.get()
    if runner is None:
        return asyncio.run(main)
    return runner.run(main, context=contextvars.copy_context())


def lent_bus() -> Bus | None:
    """The shell's open bus if it lends it to this command and we run in its loop, else None."""
    bus = _shared_bus.get()
    runner = _shell_runner.get()
    if bus is None or runner is None or bus.closed:
        return None
    try:
        loop = asyncio.get_running_loop()
    except RuntimeError:
        return None
    return bus if loop is runner.get_loop() else None


@contextmanager
def lending(runner: asyncio.Runner, bus: Bus | None) -> Iterator[None]:
    """Within: :func:`run_async` uses *runner*, :func:`lent_bus` gives *bus* (None: no bus)."""
    runner_token = _shell_runner.set(runner)
    bus_token = _shared_bus.set(bus)
    try:
        yield
    finally:
        _shared_bus.reset(bus_token)
        _shell_runner.reset(runner_token)
