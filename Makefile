# The two commands a fresh machine needs: `make demo` and `make test`.
# Both create .venv on first use and (re)install when pyproject.toml changes; both install
# every extra (pyvista for the views, dask.distributed for cluster sweeps).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin

.PHONY: demo test test-fast test-fullwave lint

demo: $(VENV)/.installed
	$(BIN)/microsim report --quick

# two pytest-xdist workers: both cores of the 2-core machines CI runs on; the kernels compiled
# once before they start (--warm-kernels, tests/conftest.py) instead of by both
test: lint
	$(BIN)/python -m pytest -n 2 --warm-kernels

# inner loop while developing: no slow and no end-to-end tests
test-fast: $(VENV)/.installed-test
	$(BIN)/python -m pytest -n 2 -m "not slow and not integration"

# the full-wave rung's tests: installs the `fullwave` extra (pySCATMECH, compiled from source:
# 3–5 min on one core, which is why `make test` leaves it out and those tests skip there)
test-fullwave: $(VENV)/.installed-test
	$(BIN)/python -m pip install --quiet -e '.[fullwave]'
	$(BIN)/python -m pytest tests/test_fullwave.py

lint: $(VENV)/.installed-test
	$(BIN)/ruff check microsim tests examples tools
	$(BIN)/ruff format --check microsim tests examples tools

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[all]'
	touch $@

# Mitsuba's LLVM backend (the `peer` extra) compiles its microfacet BSDFs only with libLLVM >= 16
# (Debian 12's default LLVM 15 aborts the process): Debian's libllvm19 where apt-get runs as root;
# elsewhere the Mitsuba adapter's tests skip, saying why
$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[all,test,peer]'
	@if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ] \
	    && ! ls /usr/lib/*/libLLVM-19.so >/dev/null 2>&1; then \
	  apt-get install -y -qq libllvm19 >/dev/null 2>&1 \
	  || (apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq libllvm19 >/dev/null 2>&1) \
	  || echo "libllvm19 not installed: the Mitsuba adapter's tests will skip"; fi
	touch $@ $(VENV)/.installed
