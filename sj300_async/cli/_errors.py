"""The error a subcommand raises to stop with one line on stderr and exit status 2."""

from __future__ import annotations

__all__ = ["CliError"]


class CliError(Exception):
    """A startup or usage problem the user can fix; its message is printed as is."""
