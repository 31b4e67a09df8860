# skysim: `make run` (set up + Yang 2014 reproduction), `make test`, `make bench`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
PIP    := $(BIN)/python -m pip
# one BLAS thread per process (see experiments/cli/main.py): small batched systems, busy 2 cores
export OPENBLAS_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1

.PHONY: run test bench clean venv

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

# benchmarks (tests/benchmarks) run under `make bench`: some call the radiative-transfer
# engine dozens of times, which would triple the suite's time on 2 cores
test: $(VENV)/.installed-test
	$(BIN)/python -m pytest -q --ignore=tests/benchmarks

bench: $(VENV)/.installed-test
	@mkdir -p .benchmarks
	$(BIN)/python -m pytest tests/benchmarks -q --benchmark-enable --benchmark-only \
		--benchmark-json=.benchmarks/latest.json -p no:randomly
	$(BIN)/python tests/benchmarks/ratios.py .benchmarks/latest.json

# results/: what the README's commands and the reproductions write
clean:
	rm -rf $(VENV) results .benchmarks .pytest_cache
