"""What every route of the HTTP northbound answers with: JSON, its errors, the drive it names.

One place for the rules docs/WORKBENCH_API.md states: JSON without NaN, an
error as ``{"error": sentence}`` (plus what a route adds) with its 4xx
status, and a path's ``LINE/NODE`` looked up the same way everywhere
(404 naming both, excerpted, when the gateway has no such drive).
"""

from __future__ import annotations

import json
from typing import Any

from aiohttp import web

from .. import GatewayDrive, GatewayView

__all__ = ["dumps", "find_drive", "json_error", "json_reply"]


def dumps(data: Any) -> str:
    """Compact JSON; NaN or infinity is a bug, never sent."""
    return json.dumps(data, separators=(",", ":"), allow_nan=False)


def json_reply(data: Any, status: int = 200) -> web.Response:
    return web.json_response(data, status=status, dumps=dumps)


def json_error(status: int, message: str, **extra: Any) -> web.HTTPException:
    """The exception that answers ``{"error": message, ...}`` with *status*."""
    error = web.HTTPException(
        text=dumps({"error": message, **extra}), content_type="application/json"
    )
    error.set_status(status)
    return error


def find_drive(gateway: GatewayView, request: web.Request) -> GatewayDrive:
    """The drive the path's ``{line}/{node}`` names.

    Raises:
        HTTPException: 404, when the gateway has no such drive.
    """
    line, node = request.match_info["line"], request.match_info["node"]
    drive = None
    if node.isascii() and node.isdigit() and len(node) <= 4:
        drive = gateway.drive(line, int(node))
    if drive is None:
        raise json_error(404, f"no drive {node[:16]!r} on line {line[:64]!r}")
    return drive
