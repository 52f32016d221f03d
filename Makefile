# gyrostar — the two commands a newcomer needs are `make run` and `make test`.
# Both create .venv when missing, install the package (editable, with dev extras),
# build the firmware host program, then run.

PYTHON   ?= python3
VENV     ?= .venv
PY       := $(VENV)/bin/python
GYROSTAR := $(VENV)/bin/gyrostar
STAMP    := $(VENV)/.installed
FW_HOST  := firmware/build/host/gyrostar-head
PYTEST_ARGS ?=
SECONDS  ?= 60

.PHONY: run test setup lint fw-host fw-test fw-arm fw-fuzz bench clean help

help:
	@echo "make run    - set up and run the coupled loop on the built-in simulated flatsat"
	@echo "make test   - set up and run every test (Python + firmware C)"
	@echo "make lint   - ruff over the Python tree"
	@echo "make bench  - speed benchmarks (ratios against plain-numpy / peer baselines)"
	@echo "make fw-arm - build the Cortex-M3 image for QEMU mps2-an385 and print its size"
	@echo "make fw-fuzz SECONDS=N - libFuzzer over the firmware decoder and dispatcher"

$(STAMP): pyproject.toml setup.py
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev]'
	@touch $@

setup: $(STAMP)

fw-host:
	@if [ -f firmware/Makefile ]; then $(MAKE) -s -C firmware host; fi

fw-test:
	@if [ -f firmware/Makefile ]; then $(MAKE) -s -C firmware test; fi

fw-arm:
	$(MAKE) -C firmware arm

fw-fuzz:
	$(MAKE) -C firmware fuzz SECONDS=$(SECONDS)

run: setup fw-host
	$(GYROSTAR) run $(RUN_ARGS)

test: setup fw-host fw-test
	$(PY) -m pytest $(PYTEST_ARGS)

lint: setup
	$(VENV)/bin/ruff check driver mocks hil tests bench setup.py

bench: setup fw-host
	$(GYROSTAR) bench

clean:
	rm -rf build dist *.egg-info firmware/build .pytest_cache
