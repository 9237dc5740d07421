"""Fuzzing the byte readers: the reply parser, the request parser, the simulator.

Three fuzzers share one set of promises (rel_fuzz_targets.check_input):
hypothesis (shrinks a failure to a minimal input), a plain mutation loop
(counts inputs by the million, needs nothing installed), and atheris
(coverage-guided, when it is installed). Plus two properties no single
input shows: the parsers take time linear in their input whatever it is (no
hang), and decoding does not keep memory per distinct value seen.
"""

from __future__ import annotations

import gc
import json
import multiprocessing
import os
import re
import subprocess
import sys
import time
import tracemalloc
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sj300_async import sj300 as sj3

from .rel_fuzz_targets import Mutator, check_decoders, check_simulator, check_stream, mutation_loop
from .rel_leaks import counting_its_own_peak, peak_rss_mib
from .rel_sizes import Sizes

pytestmark = pytest.mark.soak

HERE = Path(__file__).parent
ROOT = HERE.parent.parent

# -- hypothesis ---------------------------------------------------------------------

_PROTOCOL_BYTES = st.sampled_from(b"\x02\r\x06\x150123456789ABCDEFabcdef-GZ \x00\xff")
_REPLIES = Mutator(0).frames
noise = st.one_of(st.binary(max_size=64), st.lists(_PROTOCOL_BYTES, max_size=64).map(bytes))
streams = st.lists(st.one_of(st.sampled_from(_REPLIES), noise), max_size=8).map(b"".join)
cuts = st.lists(st.integers(min_value=0, max_value=4096), max_size=12)


def _settings(sizes: Sizes) -> settings:
    return settings(
        max_examples=sizes.hypothesis_examples,
        deadline=None,
        derandomize=os.environ.get("SJ300_CI") == "1",
        suppress_health_check=[HealthCheck.too_slow],
    )


def test_hypothesis_reply_parser(sizes: Sizes, soak_figures: dict[str, Any]) -> None:
    calls = 0

    @_settings(sizes)
    @given(data=st.one_of(streams, st.binary(max_size=1024)), cut=cuts)
    def reply_stream(data: bytes, cut: list[int]) -> None:
        nonlocal calls
        calls += 1
        check_decoders(check_stream(data, cut))

    reply_stream()
    _count(soak_figures, "hypothesis_examples", calls)


def test_hypothesis_request_parser_and_simulator(
    sizes: Sizes, soak_figures: dict[str, Any]
) -> None:
    calls = 0

    @_settings(sizes)
    @given(data=st.one_of(streams, st.binary(max_size=1024)), cut=cuts)
    def request_stream(data: bytes, cut: list[int]) -> None:
        nonlocal calls
        calls += 1
        check_stream(data, cut, requests=True)
        check_simulator(data, cut)

    request_stream()
    _count(soak_figures, "hypothesis_examples", calls)


def _count(figures: dict[str, Any], name: str, n: int) -> None:
    fuzz = figures.setdefault("fuzz", {})
    fuzz[name] = fuzz.get(name, 0) + n
    fuzz["total_inputs"] = fuzz.get("total_inputs", 0) + n


# -- the mutation loop -----------------------------------------------------------


def test_mutation_fuzz_loop(sizes: Sizes, soak_seed: int, soak_figures: dict[str, Any]) -> None:
    """The plain loop; the long form spreads it over the CPUs, one seed per worker."""
    workers = min(os.cpu_count() or 1, 4) if sizes.fuzz_inputs >= 100_000 else 1
    shares = [
        sizes.fuzz_inputs // workers + (k < sizes.fuzz_inputs % workers) for k in range(workers)
    ]
    seeds = [soak_seed * 100 + k for k in range(workers)]
    started = time.perf_counter()
    if workers == 1:
        results = [mutation_loop(seeds[0], shares[0])]
    else:
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(workers, mp_context=context) as pool:
            results = list(pool.map(mutation_loop, seeds, shares))
    elapsed = time.perf_counter() - started
    failures = [r.failure for r in results if r.failure]
    assert failures == [], failures[0]
    slowest = max(r.slowest_s for r in results)
    _count(soak_figures, "mutation_loop_inputs", sizes.fuzz_inputs)
    soak_figures["fuzz"]["mutation_loop"] = {
        "seeds": seeds,
        "processes": workers,
        "bytes": sum(r.bytes for r in results),
        "elapsed_s": round(elapsed, 1),
        "slowest_input_ms": round(slowest * 1000, 2),
        "peak_rss_mib": peak_rss_mib(),
    }
    assert slowest < 1.0, "one input took a second: something does not scale"


# -- atheris ---------------------------------------------------------------------------


def test_atheris_harness(
    sizes: Sizes, soak_seed: int, soak_figures: dict[str, Any], tmp_path: Path
) -> None:
    """The libFuzzer harness runs clean: 1,000,000 runs in the long form, a smoke run otherwise.

    The long form runs one fuzzer per CPU (two here), each with its own seed,
    sharing one corpus, and counts the runs of all of them.
    """
    import atheris  # noqa: F401  (the dev extra installs it: a missing one must fail, not skip)

    total = sizes.atheris_runs or 2000
    processes = min(os.cpu_count() or 1, 4) if total >= 100_000 else 1
    corpus = tmp_path / "corpus"
    corpus.mkdir()
    for i, frame in enumerate(_REPLIES):  # b"\x00": no cut points, then the stream
        (corpus / f"seed{i}").write_bytes(b"\x00" + frame)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(HERE)])}
    started = time.perf_counter()
    running = []
    for k in range(processes):
        log = (tmp_path / f"fuzz{k}.log").open("w")
        command = [
            sys.executable,
            str(HERE / "fuzz_parser.py"),
            f"-runs={total // processes + (k < total % processes)}",
            f"-seed={soak_seed + k}",
            # Monitor replies fit; trip histories (447 bytes) are the mutation loop's.
            "-max_len=256",
            "-timeout=10",  # one input for 10 s is a hang
            "-rss_limit_mb=1024",
            "-print_final_stats=1",
            str(corpus),
        ]
        # libFuzzer's -rss_limit_mb reads ru_maxrss, which a child started directly
        # inherits from this worker's peak (2,070 MB after the OPC UA tests once).
        fuzzer = subprocess.Popen(counting_its_own_peak(command), stderr=log, env=env, cwd=tmp_path)
        running.append((fuzzer, log))
    executed = 0
    coverage: list[tuple[str, str]] = []
    peaks = []
    for proc, log in running:
        proc.wait(timeout=3600)
        log.close()
        output = Path(log.name).read_text()
        assert proc.returncode == 0, output[-4000:]
        done = re.search(r"Done (\d+) runs", output)
        assert done, output[-2000:]
        executed += int(done.group(1))
        coverage += re.findall(r"cov: (\d+) ft: (\d+)", output)[-1:]
        peaks += [int(p) for p in re.findall(r"stat::peak_rss_mb:\s+(\d+)", output)]
    assert executed >= total
    _count(soak_figures, "atheris_runs", executed)
    soak_figures["fuzz"]["atheris"] = {
        "seeds": [soak_seed + k for k in range(processes)],
        "processes": processes,
        "elapsed_s": round(time.perf_counter() - started, 1),
        "coverage_edges": max((int(c[0]) for c in coverage), default=None),
        "coverage_features": max((int(c[1]) for c in coverage), default=None),
        "peak_rss_mb": max(peaks, default=None),
    }


# Grows its peak to argv[1] MiB and gives the memory back, then runs each command of
# argv[2] (JSON) in turn, as the test's xdist worker runs the fuzzer, and prints what each
# printed: a worker that once held much and holds little now.
_ONCE_FAT = """\
import json, subprocess, sys
held = bytearray(int(sys.argv[1]) << 20)
for page in range(0, len(held), 4096):  # resident, page by page
    held[page] = 1
del held
for command in json.loads(sys.argv[2]):
    print(subprocess.run(command, capture_output=True, text=True, check=True).stdout.strip())
"""
_PRINT_PEAK_MIB = "import resource; print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss >> 10)"


def test_the_fuzzer_is_started_counting_its_own_peak_memory() -> None:
    """A child's ru_maxrss, which libFuzzer's -rss_limit_mb checks, is its own (issue 41):
    test_atheris_harness passed alone and failed after the suite's heaviest tests."""
    probe = [sys.executable, "-c", _PRINT_PEAK_MIB]
    commands = json.dumps([probe, counting_its_own_peak(probe)])
    ran = subprocess.run(
        [sys.executable, "-c", _ONCE_FAT, "400", commands],
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    )
    direct, launched = map(int, ran.stdout.split())
    assert direct >= 400, ran.stdout  # the trap: started directly, it counts from 400 MiB
    assert launched < 64, ran.stdout  # its own: an interpreter's few MiB


# -- no hang, bounded memory -----------------------------------------------------------

_ADVERSARIAL = [  # (a unit repeated to fill the input, the smaller input size)
    pytest.param(bytes(range(256)), 1 << 18, id="noise"),
    pytest.param(b"\x02" + b"0" * 500 + b"\r", 1 << 18, id="overlong frames"),
    pytest.param(_REPLIES[5], 1 << 18, id="valid monitor replies"),
    pytest.param(b"\x02\r", 1 << 14, id="empty frames"),
    pytest.param(b"\x02" + b"7" * 399, 1 << 18, id="a frame start every 400 bytes"),
]


def _feed_cost(unit: bytes, size: int, chunk: int, repeat: int) -> float:
    """Least CPU seconds, over *repeat* runs, to feed *size* bytes of *unit* in *chunk* pieces."""
    data = (unit * (size // len(unit) + 1))[:size]
    best = float("inf")
    gc.disable()
    try:
        for _ in range(repeat):
            parser = sj3.ReplyParser()
            begin = time.thread_time()  # CPU time: other processes do not count
            for at in range(0, len(data), chunk):
                parser.feed(data[at : at + chunk])
            best = min(best, time.thread_time() - begin)
            assert parser.buffered <= parser.max_body
    finally:
        gc.enable()
    return best


@pytest.mark.parametrize(("unit", "size"), _ADVERSARIAL)
def test_parser_takes_linear_time(unit: bytes, size: int) -> None:
    """Sixteen times the input costs about sixteen times the time, whatever the bytes.

    Linear is x16 and a quadratic cost x256, so the bound of x40 leaves room
    for cache and allocation effects either way. Whole chunks matter: a TCP
    bridge hands over whatever the socket holds. (The request parser shares
    the frame splitter.)
    """
    small, large = _feed_cost(unit, size, size, 3), _feed_cost(unit, 16 * size, 16 * size, 1)
    assert large < 40 * small + 0.01, f"x16 input took {large / small:.0f}x as long"
    small, large = _feed_cost(unit, 1 << 12, 7, 3), _feed_cost(unit, 1 << 16, 7, 1)
    assert large < 40 * small + 0.01, f"in 7-byte chunks, x16 input took {large / small:.0f}x"


def test_decoding_keeps_no_memory_per_distinct_value() -> None:
    """Monitor items 5 and 6 arrive as 8 hex digits: 2**32 patterns must not mean 2**32 objects."""
    base = b"00000000" * 4

    def decode(n: int, start: int) -> None:
        for i in range(start, start + n):
            inputs, outputs = (i * 7919) & 0xFFFFFFFF, i & 0xFFFFFFFF
            sj3.decode_monitor(base + b"%08X" % inputs + b"%08X" % outputs + b"00000000" * 7)

    decode(1000, 0)  # warm up whatever is legitimately cached
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        decode(4_000, 10**6)
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert grown < 256 * 1024, f"decoding 4,000 distinct patterns kept {grown / 2**20:.1f} MiB"
