# skysim: `make run` (set up + Yang 2014 reproduction), `make test`, `make test-all`, `make bench`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
PIP    := $(BIN)/python -m pip
# one BLAS thread per process (see experiments/cli/main.py): small batched systems, busy 2 cores
export OPENBLAS_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1

.PHONY: run test test-slow test-matrix test-all bench clean venv

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(PIP) install --quiet --upgrade pip

# Stamps re-install when pyproject.toml changes. `make run` installs the extras the README's
# commands need: rt (multiple-scattering sky), sweep (sensitivity sweeps), series (netCDF sky
# series) and camera (16-bit TIFF images).
$(VENV)/.installed-run: pyproject.toml Makefile | $(BIN)/python
	$(PIP) install --quiet -e '.[rt,sweep,series,camera,moon]'
	@touch $@

$(VENV)/.installed-test: pyproject.toml Makefile | $(BIN)/python
	$(PIP) install --quiet -e '.[test,rt,sweep,series,camera,moon]'
	@touch $@ $(VENV)/.installed-run

venv: $(VENV)/.installed-run

run: $(VENV)/.installed-run
	$(BIN)/skysim reproduce yang2014
	@echo "skysim is installed in $(VENV): run it as $(BIN)/skysim ..., or once per shell"
	@echo "  . $(BIN)/activate    and then   skysim --help"

# `make test`: every test not marked slow, on TEST_WORKERS processes (pytest-xdist; a test
# module's tests share a process, so its module fixtures are built once); `make test-slow`: the
# tests marked slow (long reference runs, reproductions, recoveries on real sessions);
# `make test-matrix`: the identifiability matrices (each instrument's candidates simulated and
# diagnosed, tens of minutes); `make test-all`: all of them. Benchmarks (tests/benchmarks) run under `make bench`: some call the
# radiative-transfer engine dozens of times. A selection that collects no test (pytest exit
# 5, e.g. no slow test left) is not a failure.
TEST_WORKERS ?= 2
PYTEST := $(BIN)/python -m pytest -q --ignore=tests/benchmarks -n $(TEST_WORKERS) --dist loadscope

test: $(VENV)/.installed-test
	$(PYTEST) -m "not slow" || [ $$? -eq 5 ]

test-slow: $(VENV)/.installed-test
	$(PYTEST) -m "slow and not matrix" || [ $$? -eq 5 ]

test-matrix: $(VENV)/.installed-test
	$(PYTEST) -m matrix || [ $$? -eq 5 ]

test-all: $(VENV)/.installed-test
	$(PYTEST) || [ $$? -eq 5 ]

bench: $(VENV)/.installed-test
	@mkdir -p .benchmarks
	$(BIN)/python -m pytest tests/benchmarks -q --benchmark-enable --benchmark-only \
		--benchmark-json=.benchmarks/latest.json -p no:randomly
	$(BIN)/python tests/benchmarks/ratios.py .benchmarks/latest.json

# results/: what the README's commands and the reproductions write
clean:
	rm -rf $(VENV) results .benchmarks .pytest_cache
