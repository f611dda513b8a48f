# svgf: every target sets itself up (virtualenv + editable install) on a fresh machine.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SVGF   := $(VENV)/bin/svgf

.PHONY: venv demo test lint bench results clean lag-fixtures

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev]'
	touch $(STAMP)

demo: $(STAMP)
	$(PY) -m svgf_cli.demo

test: $(STAMP)
	$(VENV)/bin/ruff check .
	$(PY) -m pytest

lint: $(STAMP)
	$(VENV)/bin/ruff check .

bench: $(STAMP)
	$(PY) bench/run.py

results: $(STAMP)
	$(PY) -m svgf_cli.results

# Regenerates testdata/lag/ (scenes, animations, 5 x 16 frames + references; nice'd,
# about 15 CPU-minutes). See testdata/lag/README.md.
lag-fixtures: $(STAMP)
	$(PY) testdata/make_lag.py --render

clean:
	rm -rf $(VENV) demo bench/out results .pytest_cache .ruff_cache
	find svgf_cli svgf_trace -name '*.nbi' -delete -o -name '*.nbc' -delete
