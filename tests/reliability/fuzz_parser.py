"""Coverage-guided fuzzing of the parsers and the simulator with atheris (libFuzzer).

Run it as a script; every libFuzzer flag works::

    .venv/bin/pip install atheris
    .venv/bin/python tests/reliability/fuzz_parser.py -runs=1000000 -seed=300 [CORPUS_DIR]

Each input is split by a FuzzedDataProvider into cut points and a byte
stream, and goes through :func:`rel_fuzz_targets.check_input`: the reply
parser, the request parser and a simulated bus, with every promise of that
module checked. A broken promise is an AssertionError, which libFuzzer
reports as a crash together with the input that caused it.
"""

from __future__ import annotations

import sys
from pathlib import Path

import atheris

# Run as a script, this directory is on sys.path; its helpers are the package
# ``reliability`` under tests/ (as pytest and mypy import them), so tests/ goes first.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

with atheris.instrument_imports(include=["sj300_async"]):
    from reliability.rel_fuzz_targets import check_input


def test_one_input(data: bytes) -> None:
    provider = atheris.FuzzedDataProvider(data)
    cuts = [provider.ConsumeIntInRange(0, 1024) for _ in range(provider.ConsumeIntInRange(0, 8))]
    check_input(provider.ConsumeBytes(provider.remaining_bytes()), cuts)


def main() -> None:
    atheris.Setup(sys.argv, test_one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
