"""The error a subcommand raises to stop with one line on stderr."""

from __future__ import annotations

import signal
from typing import Final

__all__ = ["EXIT_ON_SIGNAL", "FAILURE", "INTERRUPTED", "USAGE", "CliError"]

#: Exit status of a usage or startup problem (bad arguments, a bad file, nothing sent).
USAGE = 2
#: Exit status of a failure on the bus (time-out, NAK, unreachable bridge) or of a
#: check that did not pass (restore verification).
FAILURE = 1
#: Exit status after Ctrl-C (SIGINT), every command's, the services' too (128 + 2).
INTERRUPTED = 130
#: How a service (``gateway``, ``simulate``) ends on each stopping signal: Ctrl-C as
#: every command, SIGTERM (a service manager's stop) as a clean exit.
EXIT_ON_SIGNAL: Final = {signal.SIGINT: INTERRUPTED, signal.SIGTERM: 0}


class CliError(Exception):
    """A problem the user can fix; its message is printed as is.

    Attributes:
        status: the exit status (:data:`USAGE` unless told otherwise).
    """

    def __init__(self, message: str, *, status: int = USAGE) -> None:
        super().__init__(message)
        self.status = status
