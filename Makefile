# Two entry points for people (see README): `make demo` and `make test`.
# Both create .venv and install everything from the package registries.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# Test processes for pytest (pytest-xdist): one per CPU by default; PYTEST_WORKERS=0 runs them in one process.
PYTEST_WORKERS ?= auto

.PHONY: demo test lint pytest cuda-compile bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,bench,batch]"
	touch $(STAMP)

demo: $(STAMP)
	$(PY) -m pscc demo --out-dir demo-output

test: lint pytest cuda-compile

lint: $(STAMP)
	$(PY) -m ruff check pscc tests tools

pytest: $(STAMP)
	$(PY) -m pytest -q -n $(PYTEST_WORKERS)

cuda-compile: $(STAMP)
	$(PY) tools/compile_cuda.py --arch 80 90

bench: $(STAMP)
	$(PY) -m pscc.bench --out BENCHMARKS.md

clean:
	rm -rf $(VENV) demo-output bench-output .pytest_cache .ruff_cache
