"""How big each reliability run is, in the default suite and with ``--soak``."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Sizes:
    #: Drive API calls in the fault soak.
    transactions: int
    #: Drive API calls in the fault soak on a 19200-baud line with duplicated and very late replies.
    reply_transactions: int
    #: Cancelled calls in the cancellation storm.
    cancellations: int
    #: Kill / restart cycles of the TCP server.
    reconnect_cycles: int
    #: Inputs of the mutation fuzz loop (each goes through both parsers and the simulator).
    fuzz_inputs: int
    #: Examples per hypothesis property.
    hypothesis_examples: int
    #: Runs of the atheris harness (0: not run in this form).
    atheris_runs: int
    #: The whole-gateway soak (test_rel_gateway_soak.py): its plant (lines of drives,
    #: polled every interval), seconds from every drive visible to the end, a sample of RSS
    #: and descriptors every sample_s, the verdict from settle_s on.
    gateway_lines: int
    gateway_drives_per_line: int
    gateway_interval_s: float
    gateway_soak_s: float
    gateway_sample_s: float
    gateway_settle_s: float


#: The default suite (and CI): every run, small enough for the whole suite to stay fast.
SHORT = Sizes(
    transactions=2_000,
    reply_transactions=300,
    cancellations=300,
    reconnect_cycles=5,
    fuzz_inputs=20_000,
    hypothesis_examples=200,
    atheris_runs=0,
    gateway_lines=2,
    gateway_drives_per_line=16,
    gateway_interval_s=0.1,
    gateway_soak_s=30.0,
    gateway_sample_s=3.0,
    gateway_settle_s=12.0,
)

#: ``make soak``: the sizes docs/RELIABILITY.md publishes.
LONG = Sizes(
    transactions=100_000,
    reply_transactions=20_000,
    cancellations=10_000,
    reconnect_cycles=100,
    fuzz_inputs=1_000_000,
    hypothesis_examples=5_000,
    atheris_runs=1_000_000,
    gateway_lines=8,
    gateway_drives_per_line=32,
    gateway_interval_s=0.1,
    gateway_soak_s=1800.0,
    gateway_sample_s=60.0,
    gateway_settle_s=300.0,
)
