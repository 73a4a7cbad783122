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

.PHONY: demo test bench system venv clean docs docs-check docs-system

demo: $(STAMP)
	$(PY) -m o3d_lsmesh.cli demo

# second pass: the solver-facing tests again on the SciPy fallback (as without scikit-sparse); the one
# that decodes a real mesh anchor batch by anchor batch refactors per batch there (minutes): first pass only
FALLBACK_TESTS := tests/test_solvers.py tests/test_fallback.py tests/test_lsmesh.py tests/test_encoding.py tests/test_selection.py
FALLBACK_SKIP := not progressive_decoding_stays_accurate_at_omega_10n

# lint, format and types first: they take seconds and fail on any finding; then the docstring examples
test: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .
	$(PY) -m mypy
	$(PY) -m pytest -p no:dash -q --doctest-modules o3d_lsmesh
	$(PY) -m pytest -p no:dash -q
	O3D_LSMESH_NO_CHOLMOD=1 $(PY) -m pytest -p no:dash -q $(FALLBACK_TESTS) -k "$(FALLBACK_SKIP)"
	$(MAKE) docs-check

# Sphinx with warnings as errors; -E rereads every source so no warning hides in a cached page.
# The gallery shows the committed docs/images pictures and does not run the examples.
docs: $(DOCS_STAMP)
	rm -rf docs/auto_examples docs/api docs/benchmarks
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

$(STAMP): setup.cfg setup.py pyproject.toml o3d_lsmesh/hierarchy/_kernel.pyx | system
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[test]'
	touch $(STAMP)

clean:
	rm -rf $(VENV) demo_out *.egg-info docs/_build docs/auto_examples docs/api docs/benchmarks docs/sg_execution_times.rst
