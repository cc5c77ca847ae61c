# `make run`: venv + install (compiles the kernels, about a minute) + `dvc repro` on the bundled samples.  `make test`:
# venv + install + the test suite (its fast tier, on every core; minutes).  `make test-all`: the slow tier as well (dvc
# pipeline runs in copies of the repository, the browser, 81 MP images, real clusters).  `make guard`: the speed guard
# (`cvpipe bench guard`).
PYTHON ?= python3
VENV ?= .venv
BIN := $(CURDIR)/$(VENV)/bin
# the build backend and the compiler of the kernels (pyproject.toml's [build-system] requires, the same pins): the
# editable install builds without isolation, so that importing cvpipe can rebuild an edited .pyx with them. Without
# isolation the dependencies that come as source (antlr4-python3-runtime, under dvc) build with the venv's own
# setuptools as well, and a venv's bundled one is too old to make wheels by itself (70.1 has bdist_wheel built in).
BUILD_REQUIRES := 'meson-python>=0.16' 'meson>=1.4' 'ninja>=1.11' 'cython>=3.0.10' 'setuptools>=70.1'

.PHONY: run test test-all test-slow guard bench benchmarks clean-venv

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

# every benchmark on $$CVPIPE_DATA into benchmarks/<name>.json, one process each, stamped with the code it measured
# (python -m cvpipe.bench.record --list names them), then BENCHMARKS.md, its plots and the README's headline column
benchmarks: $(VENV)/.installed
	@test -n "$$CVPIPE_DATA" || { echo "make benchmarks: set CVPIPE_DATA to the shared data root" >&2; exit 2; }
	PATH="$(BIN):$$PATH" $(BIN)/dvc repro samples
	export PATH="$(BIN):$$PATH"; for b in $$($(BIN)/python -m cvpipe.bench.record --list); do \
	  $(BIN)/python -m cvpipe.bench.record $$b --dir benchmarks || exit 1; done
	PATH="$(BIN):$$PATH" $(BIN)/cvpipe bench report --dir benchmarks --out BENCHMARKS.md --machine auto --readme README.md

$(VENV)/.installed: pyproject.toml meson.build
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q $(BUILD_REQUIRES)
	PATH="$(BIN):$$PATH" $(BIN)/python -m pip install -q --no-build-isolation -e '.[test]'
	touch $@

clean-venv:
	rm -rf $(VENV)
