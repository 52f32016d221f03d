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
RUN_ARGS ?= --realtime   # SCHED_FIFO for the loop thread when permitted (else it says why and runs normally)
SECONDS  ?= 60

.PHONY: run test setup lint fw-host fw-test fw-arm fw-fuzz fuzz soak bench clean help

help:
	@echo "make run    - set up and run the coupled loop on the built-in simulated flatsat"
	@echo "make test   - set up and run every test (Python + firmware C)"
	@echo "make lint   - ruff over the Python tree"
	@echo "make bench  - speed benchmarks (ratios against plain-numpy / peer baselines)"
	@echo "make fw-arm - build the Cortex-M3 image for QEMU mps2-an385 and print its size"
	@echo "make fw-fuzz SECONDS=N - libFuzzer over the firmware decoder and dispatcher"
	@echo "make fuzz   - firmware libFuzzer (FUZZ_RUNS execs) + Python hypothesis campaign (docs/RELIABILITY.md)"
	@echo "make soak   - 1 h of simulated flatsat time with random faults: RSS and overruns (SOAK_S=3600)"

$(STAMP): pyproject.toml setup.py
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev]'
	@touch $@

setup: $(STAMP)

fw-host:
	@if [ -f firmware/Makefile ]; then $(MAKE) -s -C firmware host; fi

# firmware C tests: need cmocka (libcmocka-dev), installed here when missing if we are root with
# apt-get; otherwise they are skipped with one line saying why and the Python tests still run
fw-test:
	@if [ -f firmware/Makefile ]; then $(MAKE) -s -C firmware test-or-skip; fi

fw-arm:
	$(MAKE) -C firmware arm

fw-fuzz:
	$(MAKE) -C firmware fuzz SECONDS=$(SECONDS)

# reliability campaigns (docs/RELIABILITY.md); both run niced: the machine is shared
FUZZ_RUNS ?= 10000000
FUZZ_EXAMPLES ?= 10000
SOAK_S ?= 3600
fuzz: setup
	$(MAKE) -C firmware fuzz-build
	cd firmware && mkdir -p build/fuzz/corpus build/fuzz/artifacts && nice -n 10 ./build/fuzz/fuzz-head \
	  -runs=$(FUZZ_RUNS) -dict=fuzz/head.dict -max_len=4400 -print_final_stats=1 \
	  -artifact_prefix=build/fuzz/artifacts/ build/fuzz/corpus fuzz/corpus
	GYROSTAR_FUZZ_EXAMPLES=$(FUZZ_EXAMPLES) nice -n 10 $(PY) -m pytest tests/reliability -m fuzz -q

soak: setup
	@mkdir -p build/reliability
	nice -n 5 $(PY) -m gyrostar.reliability.soak --duration $(SOAK_S) --out build/reliability/soak.json

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
