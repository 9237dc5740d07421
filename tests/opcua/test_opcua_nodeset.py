"""The standard nodeset's cache (``_nodeset``): made once, read after, never a reason not to
start."""

from __future__ import annotations

import asyncio
import logging
import os
from pathlib import Path

import pytest
from asyncua import Server, ua
from waiting import process_gone, wait_for

from sj300_async.gateway.opcua._nodeset import (
    SHELF_NAME,
    default_cache,
    initialised,
    shelf_directory,
)


async def _start(cache: Path | None) -> tuple[Server, type]:
    server = await initialised(Server, cache)
    return server, type(server.iserver.aspace._nodes)


async def _reads_the_standard(server: Server) -> None:
    """The standard's nodes answer as they do in any server (a type, the Server object)."""
    name = await server.get_node(ua.NodeId(ua.ObjectIds.BaseDataVariableType)).read_browse_name()
    assert name.Name == "BaseDataVariableType"
    limits = server.get_node(ua.NodeId(ua.ObjectIds.Server_ServerCapabilities_OperationLimits))
    assert len(await limits.get_children()) >= 12


async def test_the_first_start_makes_the_shelf_and_the_next_reads_it(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    first, table = await _start(cache)
    # Made by a child process, then read: the first start's process holds no built
    # nodes (module docstring), as any later start.
    assert table.__name__ == "LazyLoadingDict"
    await _reads_the_standard(first)
    shelf = shelf_directory(cache)
    assert (shelf / SHELF_NAME).is_file()
    assert [p.name for p in cache.iterdir()] == [shelf.name]  # no tmp-* left
    assert (cache.stat().st_mode & 0o777) == 0o700
    second, table = await _start(cache)
    assert table.__name__ == "LazyLoadingDict"  # asyncua's, reading the shelf
    await _reads_the_standard(second)


async def test_where_the_child_fails_the_nodes_are_built_here_and_the_shelf_made(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    caplog.set_level(logging.INFO, logger="sj300_async.gateway.opcua")
    monkeypatch.setattr("sys.executable", "/bin/false")  # a child that fails at once
    cache = tmp_path / "cache"
    server, table = await _start(cache)
    assert table is dict  # built from asyncua's code, in this process
    await _reads_the_standard(server)
    assert (shelf_directory(cache) / SHELF_NAME).is_file()  # and the shelf made here
    assert any("nodeset cache child failed (1" in r.getMessage() for r in caplog.records)


async def test_a_child_that_cannot_start_is_no_reason_not_to_start(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    caplog.set_level(logging.INFO, logger="sj300_async.gateway.opcua")
    monkeypatch.setattr("sys.executable", str(tmp_path / "no-such-python"))
    server, table = await _start(tmp_path / "cache")
    assert table is dict
    await _reads_the_standard(server)
    assert any("not made by a child" in r.getMessage() for r in caplog.records)


async def test_without_a_cache_the_nodes_are_built(tmp_path: Path) -> None:
    server, table = await _start(None)
    assert table is dict
    await _reads_the_standard(server)


async def test_a_shelf_that_does_not_read_is_removed_and_the_nodes_built(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    cache = tmp_path / "cache"
    await _start(cache)
    shelf = shelf_directory(cache)
    for path in shelf.iterdir():
        if path.stat().st_size:
            path.write_bytes(b"\0" * path.stat().st_size)  # a disk error
    with caplog.at_level(logging.WARNING, "sj300_async.gateway.opcua"):
        server, table = await _start(cache)
    assert table is dict
    await _reads_the_standard(server)
    assert not shelf.exists()
    assert "did not read" in caplog.text


async def test_a_cache_others_may_write_is_not_used(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    cache = tmp_path / "cache"
    cache.mkdir()
    cache.chmod(0o777)
    with caplog.at_level(logging.WARNING, "sj300_async.gateway.opcua"):
        server, table = await _start(cache)
    assert table is dict
    await _reads_the_standard(server)
    assert "writable by others" in caplog.text
    assert list(cache.iterdir()) == []  # nothing written there


async def test_a_cache_that_cannot_be_made_is_no_reason_not_to_start(tmp_path: Path) -> None:
    blocked = tmp_path / "file"
    blocked.write_text("not a directory")
    server, table = await _start(blocked / "cache")
    assert table is dict
    await _reads_the_standard(server)


async def test_a_directory_left_by_a_start_that_died_is_removed_an_hour_later(
    tmp_path: Path,
) -> None:
    cache = tmp_path / "cache"
    cache.mkdir(mode=0o700)
    dead, making = cache / "tmp-dead", cache / "tmp-making"
    for directory in (dead, making):
        directory.mkdir()
        (directory / "partial").write_bytes(b"x")
    os.utime(dead, (0, 0))
    await _start(cache)
    assert not dead.exists()
    assert making.exists()  # another start's, under way


def test_the_default_cache_is_systemd_s_then_xdg_then_home(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("CACHE_DIRECTORY", "/var/cache/sj300:/other")
    assert default_cache() == Path("/var/cache/sj300")
    monkeypatch.delenv("CACHE_DIRECTORY")
    monkeypatch.setenv("XDG_CACHE_HOME", "/x")
    assert default_cache() == Path("/x/sj300-async")
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", "/home/op")
    assert default_cache() == Path("/home/op/.cache/sj300-async")
    monkeypatch.delenv("HOME")
    assert default_cache() is None


def _sleeping_child(tmp_path: Path) -> tuple[Path, Path]:
    """A stand-in for the child (sys.executable) that writes its pid, then sleeps."""
    pid_file = tmp_path / "child.pid"
    script = tmp_path / "slow-python"
    script.write_text(f"#!/bin/sh\necho $$ > {pid_file}\nexec sleep 60\n", encoding="ascii")
    script.chmod(0o700)
    return script, pid_file


async def test_a_start_cancelled_while_the_child_works_leaves_no_child(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    script, pid_file = _sleeping_child(tmp_path)
    monkeypatch.setattr("sys.executable", str(script))
    start = asyncio.create_task(_start(tmp_path / "cache"))
    await wait_for(pid_file.exists, "the child started")
    await wait_for(lambda: pid_file.read_text().strip() != "", "its pid written")
    pid = int(pid_file.read_text())
    start.cancel()
    with pytest.raises(asyncio.CancelledError):
        await start
    assert process_gone(pid)  # killed and reaped before the cancellation went on


async def test_a_child_past_its_time_is_killed_and_the_nodes_built_here(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="sj300_async.gateway.opcua")
    script, pid_file = _sleeping_child(tmp_path)
    monkeypatch.setattr("sys.executable", str(script))
    monkeypatch.setattr("sj300_async.gateway.opcua._nodeset.CHILD_TIMEOUT_S", 0.5)
    server, table = await _start(tmp_path / "cache")
    assert table is dict
    await _reads_the_standard(server)
    assert process_gone(int(pid_file.read_text()))
    assert any("child timed out after 0.5 s" in r.getMessage() for r in caplog.records)
