# The two commands a new machine needs: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# `make demo` installs the core alone (the demo needs no extra); `make test` every extra and the test tools.
CORE_STAMP := $(VENV)/.installed-core
STAMP := $(VENV)/.installed

.PHONY: demo test lint typecheck layers pytest docs bench sysdeps clean fuzz soak supervised

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(CORE_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@

demo: $(CORE_STAMP)
	$(BIN)/vstig demo

# System packages the real-peer tests need (User-Mode Linux, can-utils, tshark, gcc).
sysdeps:
	bash tests/sysdeps.sh

lint: $(STAMP)
	$(BIN)/ruff check .

typecheck: $(STAMP)
	$(BIN)/mypy

# The import contracts in pyproject.toml ([tool.importlinter]): layers, and no cycles.
layers: $(STAMP)
	$(BIN)/lint-imports

# Foxglove's own WebSocket client and decoders from npm, for the live view's tests (tests/live, gitignored).
NODE_STAMP := tests/live/node_modules/.installed

$(NODE_STAMP): tests/live/package.json | sysdeps
	@if command -v npm >/dev/null; then \
	  (cd tests/live && npm install --silent --no-audit --no-fund --no-package-lock && touch node_modules/.installed) \
	    || echo "npm install in tests/live failed: the live view's client tests will skip"; \
	else echo "npm is missing: the live view's client tests will skip"; fi

# The vstig_msgs ROS 2 interfaces, built once per machine into ~/.cache/vstig-hw (~10 s; needs g++, sysdeps).
ROS2_STAMP := $(VENV)/.ros2-interfaces

$(ROS2_STAMP): $(STAMP) $(wildcard vstig_hw/ros2msgs/*/*.idl) vstig_hw/ros2msgs/build.py | sysdeps
	$(BIN)/python -m vstig_hw.ros2msgs env >/dev/null && touch $@

pytest: $(STAMP) sysdeps $(NODE_STAMP) $(ROS2_STAMP)
	$(BIN)/pytest

# The docs site, strict: a broken link, anchor or API reference fails. Browse it from site/index.html.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

test: lint typecheck layers docs pytest

bench: $(STAMP)
	$(BIN)/python -m benchmarks

# The long runs (not part of `make test`). FUZZ_RUNS inputs per parser; SOAK_SECONDS of gateway traffic.
FUZZ_RUNS ?= 1000000
SOAK_SECONDS ?= 600
FUZZ_STAMP := $(VENV)/.fuzz-installed

$(FUZZ_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test,fuzz]'
	touch $@

fuzz: $(FUZZ_STAMP)
	$(BIN)/python tests/fuzz/run.py --runs $(FUZZ_RUNS)

soak: $(STAMP)
	$(BIN)/python tests/soak/run.py --seconds $(SOAK_SECONDS)

# A bridge from a config file under a played systemd (notify socket, watchdog) for SUPERVISED_SECONDS: 0 lost.
SUPERVISED_SECONDS ?= 1800
supervised: $(STAMP)
	$(BIN)/python tests/soak/supervised.py --seconds $(SUPERVISED_SECONDS)

clean:
	rm -rf $(VENV) build site *.egg-info .pytest_cache .mypy_cache .ruff_cache
