# `make run`: venv + install + `dvc repro` on the bundled samples.  `make test`: venv + install + the test suite (its
# fast tier, on every core; minutes).  `make test-all`: the slow tier as well (dvc pipeline runs in copies of the
# repository, the browser, 81 MP images, real clusters).  `make guard`: the speed guard (`cvpipe bench guard`).
PYTHON ?= python3
VENV ?= .venv
BIN := $(CURDIR)/$(VENV)/bin
export NUMBA_CACHE_DIR ?= $(CURDIR)/.numba_cache

.PHONY: run test test-all test-slow guard bench clean-venv

run: $(VENV)/.installed
	PATH="$(BIN):$$PATH" $(BIN)/dvc repro

test: $(VENV)/.installed
	PATH="$(BIN):$$PATH" $(BIN)/python -m pytest -q -m "not slow" -n auto

test-slow: $(VENV)/.installed
	PATH="$(BIN):$$PATH" $(BIN)/python -m pytest -q -m slow

test-all: test test-slow

# the bundled samples first: the guard measures on them (and on $$CVPIPE_DATA where set)
guard: $(VENV)/.installed
	PATH="$(BIN):$$PATH" $(BIN)/dvc repro samples
	PATH="$(BIN):$$PATH" $(BIN)/cvpipe bench guard

bench: $(VENV)/.installed
	PATH="$(BIN):$$PATH" $(BIN)/cvpipe bench pipeline

$(VENV)/.installed: pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $@

clean-venv:
	rm -rf $(VENV)
