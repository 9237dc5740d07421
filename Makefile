# Every target creates .venv when it is missing, so a fresh machine needs only
# Python >= 3.11 and make.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint typecheck pytest bench soak clean venv

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/sj300 monitor

test: lint typecheck pytest

lint: $(STAMP)
	$(BIN)/ruff check sj300_async tests benchmarks examples
	$(BIN)/ruff format --check sj300_async tests benchmarks examples

typecheck: $(STAMP)
	$(BIN)/mypy --strict sj300_async

pytest: $(STAMP)
	$(BIN)/pytest $(PYTEST_ARGS)

bench: $(STAMP)
	$(BIN)/python -m benchmarks

# The long form of tests/reliability (docs/RELIABILITY.md); its figures are printed
# at the end and written as JSON.
SOAK_REPORT ?= $${TMPDIR:-/tmp}/sj300-soak-report.json
soak: $(STAMP)
	$(BIN)/pytest --soak -m soak --soak-report $(SOAK_REPORT) $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache .hypothesis
