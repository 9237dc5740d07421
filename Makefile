# Every target creates .venv when it is missing, so a fresh machine needs only
# Python >= 3.11 and make (and, for the tests, the system packages below and Node.js
# >= 20 with npm, for node-packages).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# The package with every extra (test, lint, bench, fuzz): what the checks need.
DEV_STAMP := $(VENV)/.installed-dev
# The package alone, without extras: what the demo runs on.
RUN_STAMP := $(VENV)/.installed-run
# The package with the gateway extra (aiomqtt, prometheus-client): `sj300 gateway` from a
# checkout, whose package `pip install 'sj300-async[gateway]'` would not install.
GATEWAY_STAMP := $(VENV)/.installed-gateway

# Debian packages the tests need, as package:command (the command tells whether it is
# installed): socat + ser2net for the serial-device-server bridge test, mbpoll as an
# independent Modbus client, mosquitto + its clients for the MQTT tests, tshark for the
# Wireshark dissector's test (its debconf question, whether non-root users may capture,
# takes its default "no" under DEBIAN_FRONTEND=noninteractive), chromium for the
# workbench page's browser tests (Playwright drives it: its own browser download is
# never run), openssl for the certificate of the workbench's HTTPS test, systemd for
# systemd-analyze (the service unit's verify and security checks; no systemd need run),
# prometheus for Prometheus and promtool (the dashboard's queries, the alerting rules).
SYSTEM_PACKAGES := socat:socat ser2net:ser2net mbpoll:mbpoll mosquitto:mosquitto \
	mosquitto-clients:mosquitto_sub tshark:tshark chromium:chromium openssl:openssl \
	systemd:systemd-analyze prometheus:promtool

# The npm packages of the OPC UA tests' independent client (tests/opcua/node: node-opcua,
# from its package-lock.json; tests/test_readme.py checks README.md against package.json).
# npm ci runs when node_modules is missing or older than the lockfile; the stamp is
# inside node_modules, so deleting node_modules installs again.
# The npm packages the tests use as independent implementations, each folder with its
# lockfile: node-opcua (tests/opcua), Eclipse Tahu's sparkplug-payload (tests/sparkplug).
NODE_DIRS := tests/opcua/node tests/sparkplug/node
NODE_STAMPS := $(addsuffix /node_modules/.installed,$(NODE_DIRS))

.PHONY: demo gateway examples test lint typecheck lint-imports docs system-packages \
	node-packages pytest attacks test-ha test-opcua-public bench bench-compare soak clean venv

# No pip self-upgrade: the venv's pip installs the package (editable, PEP 660) as it
# is, and upgrading it costs 1.5 s of the demo's first screen.
$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(DEV_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

$(RUN_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(GATEWAY_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[gateway,opcua]'
	touch $@

venv: $(DEV_STAMP)

gateway: $(GATEWAY_STAMP)
	@echo "the gateway's libraries are in $(VENV): $(BIN)/sj300 gateway --help (docs/GATEWAY.md)"

demo: $(RUN_STAMP)
	$(BIN)/sj300 monitor

# Every example against the in-memory simulator, as tests/test_examples.py runs them.
examples: $(RUN_STAMP)
	$(BIN)/python examples/one_shot.py 'sim://?nodes=1-2'
	$(BIN)/python examples/fr700_one_shot.py 'sim://?protocol=fr700&nodes=0-3'
	$(BIN)/python examples/polling_loop.py 'sim://?nodes=1-4' --duration 2
	$(BIN)/python examples/service.py 'sim://?nodes=1-3' --port 0 --run-for 2

# In this order; make stops at the first that fails.
test: lint typecheck lint-imports docs pytest

lint: $(DEV_STAMP)
	$(BIN)/ruff check sj300_async tests benchmarks examples scripts
	$(BIN)/ruff format --check sj300_async tests benchmarks examples docs scripts

typecheck: $(DEV_STAMP)
	$(BIN)/mypy --strict sj300_async tests scripts

# The import contracts in pyproject.toml ([tool.importlinter]).
lint-imports: $(DEV_STAMP)
	$(BIN)/lint-imports

# The user guide and the API reference (mkdocs.yml) into site/; --strict: a broken
# link or reference, or a docstring mkdocstrings cannot read, fails the build.
docs: $(DEV_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

# Installs the missing ones as root; otherwise names them and fails (exit 2).
system-packages:
	@missing=; \
	for entry in $(SYSTEM_PACKAGES); do \
		PATH="$$PATH:/usr/sbin:/sbin" command -v $${entry#*:} >/dev/null 2>&1 \
			|| missing="$$missing $${entry%%:*}"; \
	done; \
	if [ -z "$$missing" ]; then exit 0; fi; \
	if [ "$$(id -u)" != 0 ]; then \
		echo "the tests need these system packages: sudo apt-get install$$missing" >&2; \
		exit 2; \
	fi; \
	echo "installing system packages:$$missing"; \
	export DEBIAN_FRONTEND=noninteractive; \
	apt-get update -qq && apt-get install -y -qq $$missing >/dev/null

# Names Node.js >= 20 and npm in one line and fails (exit 2) when either is missing (or
# node is older): not installed from Debian, whose nodejs may be older than node-opcua needs.
node-packages: $(NODE_STAMPS)

%/node_modules/.installed: %/package-lock.json %/package.json
	@command -v npm >/dev/null 2>&1 \
		&& node -e 'process.exit(parseInt(process.versions.node) >= 20 ? 0 : 1)' 2>/dev/null || { \
		echo "the OPC UA and Sparkplug tests need Node.js >= 20 and npm: install them, then make node-packages" >&2; \
		exit 2; \
	}
	npm ci --prefix $* --no-audit --no-fund --loglevel=error
	touch $@

# The suite in this many worker processes (pytest-xdist; 0: all in one process, as a
# plain `pytest FILE` runs). Most tests wait on sockets, ptys and subprocesses:
# on 2 cores, 2 workers take the default suite from 536 s to 294 s.
PYTEST_WORKERS ?= 2

pytest: $(DEV_STAMP) system-packages node-packages
	$(BIN)/pytest -n $(PYTEST_WORKERS) --dist worksteal $(PYTEST_ARGS)

# Each attack of tests/adversarial alone, against a plant of its own (the default
# suite runs them all at once in one test); .ci/run runs it after make test.
attacks: $(DEV_STAMP) system-packages node-packages
	$(BIN)/pytest -n $(PYTEST_WORKERS) --dist worksteal --attacks tests/adversarial $(PYTEST_ARGS)

# The tests against a real Home Assistant (tests/home_assistant; issue 43), from PyPI into
# a venv of its own: about 800 MB and minutes to install, so not in make test, which
# checks the same discovery payloads against a schema of HA's keys. HA 2025.4.4 is the
# newest that installs on Python 3.13.0; HA_PYTHON is a Python >= 3.13 (pyenv's, by
# default). Every requirement of the integrations the tests load is installed here
# (tests/home_assistant/requirements.py), since the tests start hass --skip-pip.
HA_VERSION := 2025.4.4
HA_VENV := .venv-ha
HA_PYTHON ?= $(firstword $(wildcard $(HOME)/.pyenv/versions/3.13*/bin/python) \
	$(shell command -v python3.13))
HA_STAMP := $(HA_VENV)/.installed-$(HA_VERSION)
HA_SCREENSHOT ?= docs/guide/images/home-assistant-device.png

$(HA_STAMP): tests/home_assistant/requirements.py
	@test -n "$(HA_PYTHON)" || { echo "make test-ha needs Python >= 3.13: pyenv install 3.13, or HA_PYTHON=/path/to/python3.13" >&2; exit 2; }
	$(HA_PYTHON) -m venv $(HA_VENV)
	$(HA_VENV)/bin/python -m pip install --quiet 'homeassistant==$(HA_VERSION)'
	$(HA_VENV)/bin/python tests/home_assistant/requirements.py > $(HA_VENV)/requirements.txt
	$(HA_VENV)/bin/python -m pip install --quiet -r $(HA_VENV)/requirements.txt \
		-c $$($(HA_VENV)/bin/python -c 'import homeassistant, pathlib; print(pathlib.Path(homeassistant.__file__).parent / "package_constraints.txt")')
	touch $@

test-ha: $(DEV_STAMP) $(HA_STAMP) system-packages
	SJ300_HA_SCREENSHOT=$(HA_SCREENSHOT) $(BIN)/pytest -n0 \
		--home-assistant $(HA_VENV)/bin/hass tests/home_assistant $(PYTEST_ARGS)

# The OPC UA suite with the speed patches off (gateway/opcua/_speedups.py): asyncua's
# public path, as an asyncua release they were not tested with gets; .ci/run runs it.
test-opcua-public: $(DEV_STAMP) system-packages node-packages
	SJ300_OPCUA_SPEEDUPS=0 $(BIN)/pytest -n $(PYTEST_WORKERS) tests/opcua $(PYTEST_ARGS)

bench: $(DEV_STAMP)
	$(BIN)/python -m benchmarks $(BENCH_ARGS)

# make bench-compare REF=<commit> [BENCH_ARGS='--only codec']: that commit's
# benchmarks (in a temporary git worktree) against the working tree's.
bench-compare: $(DEV_STAMP)
	@test -n "$(REF)" || { echo "usage: make bench-compare REF=<commit> [BENCH_ARGS=...]" >&2; exit 2; }
	$(BIN)/python -m benchmarks.compare --ref '$(REF)' $(BENCH_ARGS)

# The long form of tests/reliability (docs/RELIABILITY.md); its figures are printed
# at the end and written as JSON.
SOAK_REPORT ?= $${TMPDIR:-/tmp}/sj300-soak-report.json
soak: $(DEV_STAMP)
	$(BIN)/pytest --soak -m soak --soak-report $(SOAK_REPORT) $(PYTEST_ARGS)

clean:
	rm -rf $(VENV) $(HA_VENV) .mypy_cache .ruff_cache .pytest_cache .hypothesis site
