"""One allocator behaviour for every benchmark process: glibc's malloc thresholds pinned.

glibc serves an allocation above its *mmap threshold* (128 KiB at start)
with ``mmap``, and raises the threshold whenever it frees such a chunk
while it is still large. Which state a process is in therefore depends on
what it happened to allocate and free before (its imports included), and
it changes what the same code costs:

- asyncio's plain-protocol socket reads allocate 256 KiB each: ``mmap`` +
  ``mremap`` + ``munmap`` and a page fault per read in one state, none in
  the other, so the bare tcp floor's client cost differently from one
  process to another.
- A commit that touched neither path (it added one small module to the
  library and changed its socket protocols' base class) moved pymodbus's
  reference server in the gateway benchmark and the MQTT gateway's CPU per
  published state, though neither runs the changed code. With both
  thresholds fixed, the commits before and after measured alike.

So a benchmark run fixes both thresholds at glibc's own start values
(128 KiB) through ``GLIBC_TUNABLES`` before Python starts (``python -m
benchmarks`` re-executes itself once with it; every child process inherits
it). A fixed threshold is never raised: every process of the run allocates
as a freshly started one does, the default any script or service starts
with, whatever it imported or freed before. It is the state in which our
client's reads into its own buffer save the most against a plain
protocol's; in the other fixed state (high thresholds: large allocations
from the heap, no ``mmap``) they save nothing (docs/BENCHMARKS.md, "The
allocator pin"). ``SJ300_BENCH_DYNAMIC_MALLOC=1`` leaves the dynamic
thresholds alone (to see their effect).
"""

from __future__ import annotations

import os
import platform
import sys
from collections.abc import Mapping, Sequence

__all__ = ["TUNABLES", "allocator_note", "pin_or_reexec", "pinned_environment"]

#: The glibc tunables every benchmark process runs with.
TUNABLES = "glibc.malloc.mmap_threshold=131072:glibc.malloc.trim_threshold=131072"
_OPT_OUT = "SJ300_BENCH_DYNAMIC_MALLOC"


def _applies(env: Mapping[str, str]) -> bool:
    return (
        sys.platform == "linux" and platform.libc_ver()[0] == "glibc" and env.get(_OPT_OUT) != "1"
    )


def pinned_environment(env: Mapping[str, str] | None = None) -> dict[str, str]:
    """*env* (default: this process's) with :data:`TUNABLES` added to ``GLIBC_TUNABLES``."""
    result = dict(os.environ if env is None else env)
    if not _applies(result):
        return result
    present = result.get("GLIBC_TUNABLES", "")
    if TUNABLES not in present:
        result["GLIBC_TUNABLES"] = f"{present}:{TUNABLES}" if present else TUNABLES
    return result


def pin_or_reexec(module: str, argv: Sequence[str]) -> None:
    """Re-execute ``python -m module *argv`` with the pinned thresholds, unless already pinned.

    Returns only when nothing needs doing (pinned already, not glibc, or opted out).
    """
    env = pinned_environment()
    if env.get("GLIBC_TUNABLES") == os.environ.get("GLIBC_TUNABLES"):
        return
    sys.stdout.flush()
    os.execve(sys.executable, [sys.executable, "-m", module, *argv], env)


def allocator_note() -> str:
    """One line for a run's environment: how this process's malloc was set up."""
    if TUNABLES in os.environ.get("GLIBC_TUNABLES", ""):
        return f"- allocator: glibc malloc thresholds pinned (`GLIBC_TUNABLES={TUNABLES}`)"
    return "- allocator: glibc's dynamic malloc thresholds (not pinned)"
