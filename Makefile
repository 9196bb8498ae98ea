# The two commands a new machine needs: `make demo` and `make test`.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# `make demo` installs the core alone (the demo needs no extra); `make test` every extra and the test tools.
CORE_STAMP := $(VENV)/.installed-core
STAMP := $(VENV)/.installed
# The ros2 extra's wheels re-execute every Python of the venv to set LD_LIBRARY_PATH unless this is set: vstig and
# the tests need no restart (a ROS 2 process gets the path from vstig_hw.ros2msgs; DECISIONS.md, "Only a process
# that uses ROS 2 pays for its wheels").
export _ROS_WHEELS_BOOTSTRAP_COMPLETE := 1

.PHONY: demo test lint typecheck layers pytest docs bench sysdeps clean fuzz soak supervised chaos

# setuptools' editable install of this layout (cli/ installs as vstig_cli) always ends with a 9-line "Editable
# installation" note, a warning in pip's eyes: hidden by name, so any other build warning still shows.
PIP_INSTALL := PYTHONWARNINGS='ignore:Editable installation:UserWarning' $(BIN)/python -m pip install --quiet

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(CORE_STAMP): pyproject.toml | $(BIN)/python
	$(PIP_INSTALL) -e .
	touch $@

# The compiled data path (vstig_hw._vstig) is built in place by the editable install, from libvstig and its glue:
# `make test` requires it built (VSTIG_BUILD_NATIVE=1: a compile error fails), and rebuilds it when they change.
NATIVE_SOURCES := setup.py $(wildcard vstig_hw/_cext/*.[ch] firmware_spec/libvstig/*.[ch])

$(STAMP): pyproject.toml $(NATIVE_SOURCES) | $(BIN)/python sysdeps
	VSTIG_BUILD_NATIVE=1 $(PIP_INSTALL) -e '.[test]'
	touch $@

demo: $(CORE_STAMP)
	$(BIN)/vstig demo
	@echo "next: . $(VENV)/bin/activate for vstig on PATH; $(BIN)/pip install -e '.[zenoh]' for gateways on many PCs"
	@echo "      (README.md lists every extra); 'make test' installs them all and runs every check"

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

# The suites that drive the data path, again on the pure-Python path (VSTIG_PURE=1, child processes included): the
# run above takes the compiled path, and the Python reference must keep working where it is not built. tests/native
# holds the two equal; these keep the reference itself whole (about 2 minutes).
PURE_SUITES := tests/gateway tests/api tests/cli/test_isolation.py tests/cli/test_fair_share.py \
               tests/socketcan/test_in_uml.py

# pytest's own process loads rclpy (its serializer is the CDR tests' reference): it gets the wheels' library path as
# their bootstrapper computes it, without the restart; the vstig processes of the tests run as a user's (tests/dds.py).
ROS_LIBRARY_PATH = $$($(BIN)/python -c 'from vstig_hw.ros2msgs import ros_environment as e; print(e()["LD_LIBRARY_PATH"])')

# The main pass requires the compiled data path (VSTIG_REQUIRE_NATIVE=1): its differential tests fail, never skip,
# when it did not load; the pure pass runs the suites that cover the Python path on its own.
pytest: $(STAMP) sysdeps $(NODE_STAMP) $(ROS2_STAMP)
	VSTIG_REQUIRE_NATIVE=1 LD_LIBRARY_PATH="$(ROS_LIBRARY_PATH)" $(BIN)/pytest
	VSTIG_PURE=1 $(BIN)/pytest -q $(PURE_SUITES)

# The docs site, strict: a broken link, anchor or API reference fails. Browse it from site/index.html.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

test: lint typecheck layers docs pytest

bench: $(STAMP)
	$(BIN)/python -m benchmarks

# The long runs (not part of `make test`). FUZZ_RUNS inputs per parser; SOAK_SECONDS of gateway traffic;
# CHAOS_SECONDS of three federated gateways under a fault every 30 s (`make test` runs 120 s of it).
FUZZ_RUNS ?= 1000000
SOAK_SECONDS ?= 600
CHAOS_SECONDS ?= 1800
FUZZ_STAMP := $(VENV)/.fuzz-installed

$(FUZZ_STAMP): $(STAMP)
	$(PIP_INSTALL) -e '.[test,fuzz]'
	touch $@

fuzz: $(FUZZ_STAMP)
	$(BIN)/python tests/fuzz/run.py --runs $(FUZZ_RUNS)

soak: $(STAMP)
	$(BIN)/python tests/soak/run.py --seconds $(SOAK_SECONDS)

# A bridge from a config file under a played systemd (notify socket, watchdog) for SUPERVISED_SECONDS: 0 lost.
SUPERVISED_SECONDS ?= 1800
supervised: $(STAMP)
	$(BIN)/python tests/soak/supervised.py --seconds $(SUPERVISED_SECONDS)

chaos: $(STAMP)
	$(BIN)/python tests/chaos/run.py --seconds $(CHAOS_SECONDS)

clean:
	rm -rf $(VENV) build site *.egg-info .pytest_cache .mypy_cache .ruff_cache
