"""``sj300 shell``: an interactive session on one bus, held open throughout.

Each line is a subcommand as on the command line (``status -n 3``, ``run
forward -n 1``, ``read F002``, ``params backup DIR/file.json``), parsed by
the same parsers, plus ``help [COMMAND]`` and ``exit`` / ``quit`` (or
Ctrl-D). The bus is opened once, by the options given to ``shell`` (the
same rules as every command: ``--url``, else ``$SJ300_URL``, else the
simulator of drives 1-8), and every command uses it: on ``sim://`` the
simulated drives keep their state from one command to the next.

The bus options belong to the session: a command giving ``--url``,
``--sim``, ``--protocol``, ``--timeout``, ``--retries`` or line settings
other than the session's is refused (give them to ``shell``). ``--trace``
and ``--json`` given to ``shell`` hold for every command; a command may
give them itself.

A failing command prints the command line's one-line error and the session
goes on. Ctrl-C at the prompt clears the line; during a command it stops
that command (``monitor`` runs until then) and returns to the prompt.

Exit status: an interactive session (stdin a terminal) ends with 0, as the
person at it saw each error. A scripted one (stdin not a terminal:
``sj300 shell < commands.txt``) runs every line too, then ends with 1 when
any of them failed (a command's exit status other than 0, whatever it was,
or a line the shell refused: an unknown command, bad quoting; ``help`` of
an unknown command too), else 0. The error lines on stderr say which
failed, and how; 1 says only that something did, so a script's ``set -e``
or ``&&`` stops there.

On a terminal, with :mod:`readline` (POSIX; imported here, only when it is
used): line editing, history kept in ``$SJ300_HISTORY``, else
``~/.sj300_history`` (``SJ300_HISTORY=`` keeps none), and Tab completion of
command names, options, choices and parameter codes (the catalogue of the
bus's protocol: SJ300 codes, FR-700 ``Pr.N``). Without readline, or when stdin is
not a terminal, lines are read plainly (``sj300 shell < commands.txt``).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import shlex
import sys
import traceback
from collections.abc import Callable, Iterator
from contextlib import AsyncExitStack, suppress
from pathlib import Path
from typing import Any, Final

from ..bus import Bus
from . import _Expected, _fail, _first_expected, build_parser
from ._common import (
    DEFAULT_URL,
    add_bus_options,
    add_json_option,
    bus_url,
    command_name,
    misplaced_option,
    open_cli_bus,
    profile_of,
)
from ._errors import FAILURE, USAGE, CliError
from ._session import lending

__all__ = ["add_parser"]

#: The environment variable naming the history file.
ENV_HISTORY: Final = "SJ300_HISTORY"
#: The history file when the environment does not name one.
DEFAULT_HISTORY: Final = "~/.sj300_history"
_HISTORY_LENGTH: Final = 1000

PROMPT: Final = "sj300> "
_EXIT: Final = ("exit", "quit")
#: The options that choose and configure a bus: the session's, not a command's.
_SESSION_DESTS: Final = (
    "url",
    "sim",
    "protocol",
    "timeout",
    "retries",
    "baud",
    "parity",
    "bytesize",
    "stopbits",
)
#: Global options a command takes from the session unless it gives them.
_INHERITED_DESTS: Final = ("trace", "json")
#: Arguments whose values are parameter codes (``read``, ``write``, ``params backup --codes``).
_CODE_DESTS: Final = frozenset({"code", "codes"})
#: A global option's default in the shell's parser: not given on the line.
_UNSET: Final = object()


def add_parser(subparsers: Any) -> None:
    """Add ``shell`` to the ``sj300`` subcommands."""
    p = subparsers.add_parser(
        "shell",
        help="an interactive session on one bus (sim:// drives keep their state)",
        description="Run commands interactively on one bus held open for the session: "
        "`status -n 3`, `run forward -n 1`, `read F002`... as on the command line; `help`, "
        "`exit`. On sim:// the simulated drives keep their state from one command to the next.",
    )
    add_json_option(p)
    add_bus_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Hold the bus and run commands until ``exit`` or end of input; return the status.

    0, or 1 when stdin is not a terminal and a line failed (the module's docstring).
    """
    url = bus_url(args) or DEFAULT_URL
    with asyncio.Runner() as runner:
        stack = AsyncExitStack()
        bus = runner.run(stack.enter_async_context(open_cli_bus(args, url)))
        try:
            return _Shell(args, url, runner, bus).loop()
        finally:
            runner.run(stack.aclose())


class _Shell:
    """The read-run loop."""

    def __init__(
        self, args: argparse.Namespace, url: str, runner: asyncio.Runner, bus: Bus
    ) -> None:
        self._args = args
        self._url = url
        self._runner = runner
        self._bus = bus
        self._parser = build_parser()
        self._defaults = _unset_global_defaults(self._parser)
        self._commands = _subcommands(self._parser)
        self._commands.pop("shell", None)
        self._interactive = sys.stdin.isatty()
        self._failed = False  # a line failed: a scripted session's status is 1

    def loop(self) -> int:
        """Read and run lines until ``exit`` or end of input; return the session's status."""
        history = _History.open(self._completer()) if self._interactive else None
        prompt = PROMPT if self._interactive else ""
        if self._interactive:
            simulated = " (simulated drives keep their state until you leave)"
            print(f"sj300 shell on {self._url}{simulated if self._bus.simulator else ''}")
            print("help lists the commands; exit, quit or Ctrl-D leaves.")
        try:
            while True:
                try:
                    line = input(prompt)
                except KeyboardInterrupt:  # clears the line
                    print()
                    continue
                except EOFError:
                    if self._interactive:
                        print()
                    return self._status()
                if not self.execute(line):
                    return self._status()
        finally:
            if history is not None:
                history.save()

    def _status(self) -> int:
        """The session's exit status: 1 when a scripted session had a failure, else 0."""
        return FAILURE if self._failed and not self._interactive else 0

    def execute(self, line: str) -> bool:
        """Run one line; False when it ends the session."""
        try:
            words = shlex.split(line, comments=True)
        except ValueError as exc:
            self._error(str(exc))
            return True
        if not words:
            return True
        name = words[0]
        if name in _EXIT:
            return False
        if name == "help":
            self._help(words[1:])
        elif name == "shell":
            self._error("this is the shell already")
        elif name not in self._commands and not name.startswith("-"):
            self._error(f"no command {name!r} (help lists them)")
        elif self._run(words) != 0:  # a command, or global options before one
            self._failed = True
        return True

    def _run(self, words: list[str]) -> int:
        """Parse and run a command as ``sj300 WORDS`` would, on the session's bus."""
        try:
            args = self._parser.parse_args(words)
            run_command: Callable[[argparse.Namespace], int] | None = getattr(args, "run", None)
            if run_command is None or command_name(args) == "shell":
                self._error("this is the shell already" if run_command else "no command given")
                return USAGE
            misplaced = misplaced_option(args)
            if misplaced is not None:
                self._parser.error(misplaced)
        except SystemExit as done:  # a usage error (printed) or --help
            return done.code if isinstance(done.code, int) else USAGE
        refused = self._session_options(args)
        if refused is not None:
            return _fail(args, refused)
        try:
            with lending(self._runner, self._bus):
                return int(run_command(args))
        except KeyboardInterrupt:
            print()
            return 130
        except _Expected as exc:
            return _fail(args, exc)
        except BaseExceptionGroup as group:
            leaf = _first_expected(group)
            if leaf is None:
                traceback.print_exc()
                return 1
            return _fail(args, leaf)
        except SystemExit as done:
            return done.code if isinstance(done.code, int) else 1
        except Exception:  # a bug: show it, but keep the session (and its drives' state)
            traceback.print_exc()
            return 1

    def _session_options(self, args: argparse.Namespace) -> CliError | None:
        """Give *args* the session's global options; an error when it names another bus.

        Each command then names the session's bus explicitly (``--url``, no
        ``--sim``): ``monitor`` polls it, rather than running its demo.
        """
        for dest in _INHERITED_DESTS:
            if getattr(args, dest, None) is _UNSET:
                setattr(args, dest, getattr(self._args, dest, self._defaults[dest]))
        if not getattr(args, "takes_bus_options", False):  # simulate: nothing of the bus
            for dest in _SESSION_DESTS:
                if getattr(args, dest, None) is _UNSET:
                    setattr(args, dest, self._defaults[dest])
            return None
        session: dict[str, object] = {
            dest: getattr(self._args, dest, None) for dest in _SESSION_DESTS
        }
        session |= {"url": self._url, "sim": False, "retries": self._bus.retries}
        for dest in _SESSION_DESTS:
            value = getattr(args, dest, _UNSET)
            agrees = (
                value is _UNSET
                or value == session[dest]
                or (dest == "sim" and self._bus.simulator is not None)
                or (dest == "protocol" and value == self._bus.dialect.name)
            )
            if not agrees:
                option = "--" + dest.replace("_", "-")
                return CliError(
                    f"{option} belongs to the session (its bus is {self._url}): give it to `shell`"
                )
            setattr(args, dest, session[dest])
        return None

    def _error(self, message: str) -> None:
        """A line the shell itself refuses: one line on stderr, and the session has failed."""
        self._failed = True
        print(f"sj300 shell: error: {message}", file=sys.stderr, flush=True)

    def _help(self, words: list[str]) -> None:
        if words:
            if words[0] in self._commands:
                self._run([*words, "--help"])
            else:
                self._error(f"no command {words[0]!r} (help lists them)")
            return
        width = max(len(name) for name in self._commands) + 2
        print("commands (COMMAND --help, or help COMMAND, for its options):")
        for name, parser in self._commands.items():
            summary = _summary(self._parser, name) or parser.description or ""
            print(f"  {name:<{width}}{summary}")
        print(f"  {'help':<{width}}this list, or help COMMAND")
        print(f"  {'exit':<{width}}leave (also quit, Ctrl-D)")
        print(f"The bus, for the whole session: {self._url}")

    def _completer(self) -> _Completer:
        codes = list(profile_of(self._bus).parameters.codes())
        return _Completer(self._parser, self._commands, codes)


class _Completer:
    """Tab completion: command names, then options, choices and parameter codes."""

    def __init__(
        self,
        parser: argparse.ArgumentParser,
        commands: dict[str, argparse.ArgumentParser],
        codes: list[str],
    ) -> None:
        self._parser = parser
        self._commands = commands
        self._codes = codes
        self._matches: list[str] = []

    def candidates(self, before: str, text: str) -> list[str]:
        """What may replace *text*, the word being typed after *before*."""
        words = before.split()
        if not words:
            names = [*self._commands, "help", *_EXIT]
            return sorted(n for n in names if n.startswith(text))
        if words[0] == "help":
            return (
                sorted(n for n in self._commands if n.startswith(text)) if len(words) == 1 else []
            )
        parser = self._commands.get(words[0])
        if parser is None:
            return []
        for word in words[1:]:
            nested = _subcommands(parser)
            if word in nested:
                parser = nested[word]
        wanted: list[str] = []
        last = words[-1] if len(words) > 1 else ""
        takes_value = _option(parser, last)
        if takes_value is not None and takes_value.nargs != 0:
            if takes_value.dest in _CODE_DESTS:
                wanted = self._codes
            elif takes_value.choices is not None:
                wanted = [str(c) for c in takes_value.choices]
        elif text.startswith("-"):
            wanted = [s for a in parser._actions for s in a.option_strings if s.startswith("--")]
        else:
            for action in parser._actions:
                if action.option_strings:
                    continue
                if isinstance(action, argparse._SubParsersAction):
                    wanted.extend(action.choices)
                elif action.dest in _CODE_DESTS:
                    wanted.extend(self._codes)
                elif action.choices is not None:
                    wanted.extend(str(c) for c in action.choices)
        upper = text.upper()
        return sorted({w for w in wanted if w.upper().startswith(upper)})

    def __call__(self, text: str, state: int) -> str | None:
        """readline's completer: the *state*-th candidate for *text*."""
        if state == 0:
            import readline

            before = readline.get_line_buffer()[: readline.get_begidx()]
            try:  # with the space readline does not add under Python: on to the next word
                self._matches = [f"{word} " for word in self.candidates(before, text)]
            except Exception:  # readline would swallow it: offer nothing
                self._matches = []
        return self._matches[state] if state < len(self._matches) else None


class _History:
    """readline's history file, and its completion set up."""

    def __init__(self, path: Path | None) -> None:
        self._path = path

    @classmethod
    def open(cls, completer: _Completer) -> _History | None:
        """Set up readline; None when there is no readline."""
        try:
            import readline
        except ImportError:  # Windows, or a Python built without it
            return None
        readline.set_completer(completer)
        readline.set_completer_delims(" \t\n")
        if "libedit" in (readline.__doc__ or ""):
            readline.parse_and_bind("bind ^I rl_complete")
        else:
            readline.parse_and_bind("tab: complete")
        readline.set_history_length(_HISTORY_LENGTH)
        path = _history_path()
        if path is not None:
            with suppress(OSError):  # none yet, or unreadable: start afresh
                readline.read_history_file(path)
        return cls(path)

    def save(self) -> None:
        """Write the history file (quietly not, when it cannot be written)."""
        if self._path is None:
            return
        import readline

        with suppress(OSError):
            readline.write_history_file(self._path)


def _history_path() -> Path | None:
    value = os.environ.get(ENV_HISTORY)
    if value is None:
        return Path(DEFAULT_HISTORY).expanduser()
    return Path(value).expanduser() if value else None


def _unset_global_defaults(parser: argparse.ArgumentParser) -> dict[str, Any]:
    """Default *parser*'s global options to :data:`_UNSET`; return their defaults.

    They are the main parser's (a subcommand's copies default to SUPPRESS:
    the main parser's value stays unless given after the subcommand).
    """
    defaults: dict[str, Any] = {}
    for action in parser._actions:
        if action.dest in (*_SESSION_DESTS, *_INHERITED_DESTS):
            defaults[action.dest] = action.default
            action.default = _UNSET
    return defaults


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """*parser*'s subcommands by name (empty when it has none)."""
    found: dict[str, argparse.ArgumentParser] = {}
    for action in _subparser_actions(parser):
        found.update(action.choices)
    return found


def _subparser_actions(
    parser: argparse.ArgumentParser,
) -> Iterator[argparse._SubParsersAction[Any]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            yield action


def _summary(parser: argparse.ArgumentParser, name: str) -> str | None:
    """The one-line help ``sj300 --help`` shows for subcommand *name*."""
    for action in _subparser_actions(parser):
        for choice in action._choices_actions:
            if choice.dest == name:
                return choice.help
    return None


def _option(parser: argparse.ArgumentParser, word: str) -> argparse.Action | None:
    """The option of *parser* spelled *word*, if it is one."""
    if not word.startswith("-"):
        return None
    for action in parser._actions:
        if word in action.option_strings:
            return action
    return None
