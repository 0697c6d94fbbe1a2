# datagen: every target that needs the environment depends on $(STAMP), so a fresh
# clone needs nothing but `make test` or `make dataset`.
SHELL := /bin/bash
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp

.PHONY: install test bench-gws clean-venv

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	# torch first, from the local CPU wheel: a later torch request is then already
	# satisfied and never resolves a CUDA build.
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e '.[dev]'
	$(PY) -c "import torch, sys; v = torch.__version__; sys.exit(0 if v.startswith('2.13.0') else 'unexpected torch ' + v)"
	touch $(STAMP)

install: $(STAMP)

test: $(STAMP)
	$(PY) -m pytest -q tests

bench-gws: $(STAMP)
	$(PY) -m benchmarks.bench_gws

clean-venv:
	rm -rf $(VENV)
