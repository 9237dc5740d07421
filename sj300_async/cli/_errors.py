"""The error a subcommand raises to stop with one line on stderr."""

from __future__ import annotations

__all__ = ["FAILURE", "USAGE", "CliError"]

#: Exit status of a usage or startup problem (bad arguments, a bad file, nothing sent).
USAGE = 2
#: Exit status of a failure on the bus (time-out, NAK, unreachable bridge) or of a
#: check that did not pass (restore verification).
FAILURE = 1


class CliError(Exception):
    """A problem the user can fix; its message is printed as is.

    Attributes:
        status: the exit status (:data:`USAGE` unless told otherwise).
    """

    def __init__(self, message: str, *, status: int = USAGE) -> None:
        super().__init__(message)
        self.status = status
