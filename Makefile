# `make run`: venv + install + `dvc repro` on the bundled samples.  `make test`: venv + install + the test suite.
PYTHON ?= python3
VENV ?= .venv
BIN := $(CURDIR)/$(VENV)/bin
export NUMBA_CACHE_DIR ?= $(CURDIR)/.numba_cache

.PHONY: run test test-fast bench clean-venv

run: $(VENV)/.installed
	PATH="$(BIN):$$PATH" $(BIN)/dvc repro

test: $(VENV)/.installed
	PATH="$(BIN):$$PATH" $(BIN)/python -m pytest -q

# the inner loop: everything but the slow tier (dvc pipeline runs, the browser, 81 MP images, real clusters)
test-fast: $(VENV)/.installed
	PATH="$(BIN):$$PATH" $(BIN)/python -m pytest -q -m "not slow"

bench: $(VENV)/.installed
	PATH="$(BIN):$$PATH" $(BIN)/cvpipe bench pipeline

$(VENV)/.installed: pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $@

clean-venv:
	rm -rf $(VENV)
