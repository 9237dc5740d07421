"""OPC UA's standard nodeset, kept on disk and read as a client needs it.

Every OPC UA server holds the standard's own nodes (namespace 0: the types,
the Server object): asyncua builds them at start from generated code, some
9,000 nodes. In the gateway's process that was 50 MB of resident size and
1.2 s of every start (issue 44: a plant's box counts both). asyncua can
instead keep them in a ``shelve`` file and load each node the first time it
is looked up (``Server.init(shelf_file)``, its public API, meant for small
devices); a client browsing the types loads what it browses.

Decisions:

- **Where.** ``nodeset_cache`` in ``[opcua]`` names a directory (relative
  to the configuration file; ``""`` turns the cache off). Without it:
  ``$CACHE_DIRECTORY`` (what systemd's ``CacheDirectory=`` sets), else
  ``$XDG_CACHE_HOME/sj300-async``, else ``~/.cache/sj300-async``.
- **One file per asyncua and Python**, named by both
  (``asyncua-2.1.0-py3.11/``): a shelf holds pickled asyncua objects,
  which only the same releases read.
- **Made once, whole or not at all.** asyncua writes the shelf in a
  directory of its own, which is renamed into place when complete: two
  gateways starting together each make one, one of them is kept, and a
  start that dies half-way leaves no half shelf (only a directory
  ``tmp-*``, removed by a start an hour later).
- **Made in a child process** (``python -m
  sj300_async.gateway.opcua._nodeset DIRECTORY``), which the start awaits
  without blocking the loop, then read like any later start's. Built in
  the gateway's own process, the standard nodes' 50 MB stayed resident for
  the process's life after the server was made again from the shelf
  (Python's arenas stay fragmented; issue 44): a first start, after an
  install or an asyncua upgrade, kept 50 MB more than every start after
  it. Where the child cannot run or fails, the nodes are built in the
  process as before, and the reason is logged.
- **Trusted only when ours.** A shelf is unpickled: the cache directory
  must belong to the gateway's user and be writable by nobody else (as
  ssh treats its keys), or it is not used (a WARNING says why).
- **Never a reason not to start.** No cache directory, one not writable,
  a shelf that will not open: the nodes are built as before and one line
  says why. The first lookups of a shelf that reads wrong at start (a disk
  error) find it in asyncua's own start (it reads and writes nodes of it),
  and the server is made again without it.
- asyncua looks for the shelf's file by its name, or with ``.db``; Python's
  ``dbm.dumb`` (the only dbm some builds have) names its files ``.dat`` and
  ``.dir``. An empty file of the shelf's own name is written beside them,
  which asyncua finds and ``dbm`` passes over (``dbm.whichdb`` looks for
  the others first).
"""

from __future__ import annotations

import asyncio
import importlib.metadata
import logging
import os
import shutil
import stat
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:  # asyncua is imported with the server, not with the configuration
    from asyncua import Server

__all__ = [
    "SHELF_NAME",
    "default_cache",
    "initialised",
    "prepare",
    "publish",
    "shelf_directory",
]

_log = logging.getLogger("sj300_async.gateway.opcua")

#: The shelf's name within its directory.
SHELF_NAME: Final = "nodeset"
#: A directory being made this much older is one whose start died (a make takes seconds).
STALE_S: Final = 3600.0
#: Seconds the child making a shelf has (about 3 s here: asyncua's import and the build).
CHILD_TIMEOUT_S: Final = 120.0


def default_cache() -> Path | None:
    """The cache directory when the configuration names none (module docstring)."""
    systemd = os.environ.get("CACHE_DIRECTORY", "").split(":")[0]
    if systemd:
        return Path(systemd)
    xdg = os.environ.get("XDG_CACHE_HOME", "")
    if xdg:
        return Path(xdg) / "sj300-async"
    home = os.environ.get("HOME", "")
    return Path(home) / ".cache" / "sj300-async" if home else None


def shelf_directory(cache: Path) -> Path:
    """The directory of the shelf this process's asyncua and Python read."""
    version = importlib.metadata.version("asyncua")
    python = f"py{sys.version_info.major}.{sys.version_info.minor}"
    return cache / f"asyncua-{version}-{python}"


def _private(directory: Path) -> str | None:
    """Why *directory* is not the gateway's own (None: it is)."""
    info = directory.stat()
    if info.st_uid != os.geteuid():
        return f"{directory} belongs to another user"
    if info.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"{directory} is writable by others"
    return None


def prepare(cache: Path | None) -> tuple[Path | None, Path | None]:
    """The shelf to load (an existing one) or to make (in a new directory), or neither:
    ``(load, make)``; why neither is said once (module docstring)."""
    if cache is None:
        return None, None
    try:
        cache.mkdir(mode=0o700, parents=True, exist_ok=True)
        why = _private(cache)
        if why is not None:
            _log.warning("opcua: nodeset cache not used: %s", why)
            return None, None
        for stale in cache.glob("tmp-*"):  # a start that died making one (not one making)
            if time.time() - stale.stat().st_mtime > STALE_S:
                shutil.rmtree(stale, ignore_errors=True)
        ready = shelf_directory(cache)
        if (ready / SHELF_NAME).is_file():
            return ready / SHELF_NAME, None
        made = Path(tempfile.mkdtemp(prefix="tmp-", dir=cache))
        return None, made / SHELF_NAME
    except OSError as exc:
        _log.info("opcua: nodeset cache not used (%s): the standard nodes are built", exc)
        return None, None


def publish(made: Path) -> None:
    """Put the shelf just made at *made* in place (another start's, if it was first)."""
    (made.parent / SHELF_NAME).touch()  # asyncua finds the shelf by this name
    ready = shelf_directory(made.parent.parent)
    try:
        made.parent.rename(ready)
    except OSError:  # another start put one there first: keep it
        shutil.rmtree(made.parent, ignore_errors=True)
        return
    _log.info("opcua: standard nodeset cached in %s", ready)


def discard(shelf: Path) -> None:
    """Remove a shelf that did not read (the next start makes one again)."""
    _log.warning("opcua: the nodeset cache %s did not read: removed, nodes built", shelf.parent)
    shutil.rmtree(shelf.parent, ignore_errors=True)


async def _made_by_a_child(make: Path) -> bool:
    """Have a child process make the shelf at *make*, and publish it: False (said why)
    when it could not."""
    try:
        child = await asyncio.create_subprocess_exec(
            sys.executable, "-m", __name__, str(make),
            stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.DEVNULL,
            stderr=asyncio.subprocess.PIPE,
        )  # fmt: skip
    except OSError as exc:
        _log.info("opcua: nodeset cache not made by a child (%s): built here", exc)
        return False
    try:
        async with asyncio.timeout(CHILD_TIMEOUT_S):
            _, err = await child.communicate()
    except TimeoutError:
        _log.info("opcua: nodeset cache child timed out after %s s: built here", CHILD_TIMEOUT_S)
        return False
    finally:
        if child.returncode is None:  # timed out, or the start was cancelled: no orphan
            child.kill()
            await asyncio.shield(child.wait())
    if child.returncode != 0:
        last = err.decode(errors="replace").strip().splitlines()[-1:] or ["no message"]
        _log.info("opcua: nodeset cache child failed (%s, %s): built here", child.returncode,
                  last[0][:200])  # fmt: skip
        return False
    await asyncio.to_thread(publish, make)
    return True


async def initialised(make_server: Callable[[], Server], cache: Path | None) -> Server:
    """A server from *make_server*, initialised, its standard nodes from the shelf in
    *cache* where there is one (made there where not, by a child process; see the
    module docstring)."""
    load, make = prepare(cache)
    if make is not None and await _made_by_a_child(make):
        load, make = prepare(cache)  # the one just made, or another start's
    server = make_server()
    try:
        await server.init(load or make)
    except Exception:
        if load is None:
            raise
        discard(load)
        server = make_server()
        await server.init()
    if make is not None:
        await asyncio.to_thread(publish, make)
    return server


async def _make(shelf: Path) -> None:
    """The child's work: asyncua builds its standard nodes and writes them to *shelf*."""
    from asyncua import Server

    await Server().init(shelf)


if __name__ == "__main__":  # the child of _made_by_a_child
    asyncio.run(_make(Path(sys.argv[1])))
