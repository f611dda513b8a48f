# svgf: every target sets itself up (virtualenv + editable install) on a fresh machine.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SVGF   := $(VENV)/bin/svgf

# Blender as a Python module, for `make cycles-fixtures` only (CI never runs it): bpy 4.5 LTS
# needs Python 3.11 (bpy 5.0 writes only Combined to multilayer EXR from a script).
PYTHON_BLENDER ?= python3.11
BLENDER_VENV   := .venv-blender
BLENDER_STAMP  := $(BLENDER_VENV)/.installed

.PHONY: venv demo test lint bench results clean cycles-fixtures mitsuba-fixtures lag-fixtures mutation mutation-report

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev]'
	touch $(STAMP)

demo: $(STAMP)
	$(PY) -m svgf_cli.demo

# pytest-xdist: TEST_WORKERS processes, worksteal balancing; on a clean clone they share numba's
# compile through its on-disk cache (tests/conftest.py orders their shares). TEST_WORKERS=0: one.
TEST_WORKERS ?= 2

test: $(STAMP)
	$(VENV)/bin/ruff check .
	$(PY) -m pytest -n $(TEST_WORKERS) --dist worksteal

lint: $(STAMP)
	$(VENV)/bin/ruff check .

# Mutation testing of filters/, io/ and the runner with cosmic-ray (docs/development.md):
# hours on 2 cores; resumable (run again to go on), e.g.
# make mutation MUTATION_ARGS="--package io --minutes 60"
MUTATION_STAMP := $(VENV)/.mutation-installed
MUTATION_ARGS  ?=

$(MUTATION_STAMP): $(STAMP)
	$(PY) -m pip install -q -e '.[dev,mutation]'
	touch $(MUTATION_STAMP)

mutation: $(MUTATION_STAMP)
	nice -n 10 $(PY) tests/mutants/mutation.py run $(MUTATION_ARGS)

mutation-report: $(MUTATION_STAMP)
	$(PY) tests/mutants/mutation.py report --diff

bench: $(STAMP)
	$(PY) bench/run.py

# ColorVideoVDP for `make results` (optional extra `perceptual`, kept out of `make test`):
# torch==2.13.0 first (where a local CPU wheel exists pip takes it: small), then cvvdp.
# torchvision only has to match torch's version (cvvdp uses its Gaussian blur; a CPU torch
# next to PyPI's CUDA-built torchvision gets a stand-in, svgf_cli/evaluate/perceptual.py).
PERCEPTUAL_STAMP := $(VENV)/.perceptual-installed

$(PERCEPTUAL_STAMP): $(STAMP)
	$(PY) -m pip install -q 'torch==2.13.0' 'torchvision==0.28.0' || $(PY) -m pip install -q torch torchvision
	$(PY) -m pip install -q -e '.[dev,perceptual]'
	touch $(PERCEPTUAL_STAMP)

results: $(PERCEPTUAL_STAMP)
	$(PY) -m svgf_cli.results

$(BLENDER_STAMP):
	test -x $(BLENDER_VENV)/bin/python || $(PYTHON_BLENDER) -m venv $(BLENDER_VENV)
	$(BLENDER_VENV)/bin/python -m pip install -q "bpy==4.5.*"
	touch $(BLENDER_STAMP)

# Re-renders testdata/cycles (about 20 minutes on two cores); see testdata/cycles/README.md.
cycles-fixtures: $(BLENDER_STAMP)
	nice -n 10 $(BLENDER_VENV)/bin/python testdata/cycles/render.py

# Mitsuba 3 (CPU, scalar_rgb) next to this project, for `make mitsuba-fixtures` only (CI never
# runs it): re-renders testdata/mitsuba (about 25 minutes on two cores).
MITSUBA_VENV  := .venv-mitsuba
MITSUBA_STAMP := $(MITSUBA_VENV)/.installed

$(MITSUBA_STAMP): pyproject.toml
	test -x $(MITSUBA_VENV)/bin/python || $(PYTHON) -m venv $(MITSUBA_VENV)
	$(MITSUBA_VENV)/bin/python -m pip install -q "mitsuba==3.9.*" -e .
	touch $(MITSUBA_STAMP)

mitsuba-fixtures: $(MITSUBA_STAMP)
	for scene in seq lag/shadow lag/light_slide_dim lag/light_step; do \
		nice -n 10 $(MITSUBA_VENV)/bin/python testdata/mitsuba/render.py --scene $$scene || exit 1; \
	done

# Regenerates testdata/lag/ (scenes, animations, 5 x 16 frames + references; nice'd,
# about 15 CPU-minutes). See testdata/lag/README.md.
lag-fixtures: $(STAMP)
	$(PY) testdata/make_lag.py --render

clean:
	rm -rf $(VENV) demo bench/out results .pytest_cache .ruff_cache
	find svgf_cli svgf_trace -name '*.nbi' -delete -o -name '*.nbc' -delete
