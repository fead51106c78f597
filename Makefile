# shtools — every target sets itself up: a fresh machine needs only Python >= 3.11 and make.
#   make demo    create .venv, install, bake the bundled demo scene into out/
#   make test    create .venv if needed, install with the test extra, run the suite (not slow)
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
# Reinstall whenever pyproject.toml changes (the stamp's name carries its checksum).
STAMP  := $(VENV)/.installed-$(shell cksum < pyproject.toml | cut -d' ' -f1)
OUT    ?= out
QUICK  ?=
ONLY   ?=
GLTF_VALIDATOR := 2.0.0-dev.3.10
THREE_JS       := 0.170.0

.DEFAULT_GOAL := help
.PHONY: help demo test test-slow test-core test-extras bench lint clean golden examples

help: ## Show this help
	@echo "shtools make targets (a fresh clone needs only $(PYTHON) >= 3.11 and make):"
	@grep -E '^[a-zA-Z_-]+:.*?## ' $(MAKEFILE_LIST) | awk 'BEGIN {FS = ":.*?## "}; {printf "  \033[36m%-8s\033[0m %s\n", $$1, $$2}'
	@echo "Variables: PYTHON=$(PYTHON)  OUT=$(OUT) (demo output)  QUICK=1 (short benchmarks)  ONLY=\"a b\" (re-run some)"

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
	  { echo "error: shtools needs Python >= 3.11; run e.g. 'make PYTHON=python3.11 $(MAKECMDGOALS)'" >&2; exit 1; }
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[all,distributed,test,bench]'
	@# the Khronos glTF validator and three.js (npm) for the export tests, when npm is there
	command -v npm >/dev/null && npm install --silent --no-audit --no-fund \
	  --prefix $(VENV)/node gltf-validator@$(GLTF_VALIDATOR) three@$(THREE_JS) \
	  || echo "note: npm not found; the glTF export tests use a strict reader only"
	rm -f $(VENV)/.installed-* && touch $@

demo: $(STAMP) ## Set up and bake the bundled demo scene into out/ (baked.h5, GLB, PNGs)
	OPENBLAS_NUM_THREADS=1 $(PY) -m shtools.demo $(OUT)

test: $(STAMP) ## Set up and run the test suite (2 workers; the slow fits: make test-slow)
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -n 2 -q -m "not slow"

test-slow: $(STAMP) ## The slow tests (long sphere fits and bakes), a separate CI step
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -n 2 -q -m slow

# The runtime's tests that need nothing but the core install (numpy + h5py).
CORE_TESTS := tests/runtime/test_accumulate.py tests/runtime/test_fast_paths.py \
	tests/runtime/test_self_shadow.py tests/runtime/test_shading.py \
	tests/runtime/test_parallel.py tests/sh/test_quadrature.py tests/sh/test_tables.py \
	tests/sh/test_zonal.py tests/sh/test_cached_returns.py tests/formats/test_light_asset.py \
	tests/formats/test_compare.py tests/formats/test_atomic_mode.py \
	tests/test_runtime_imports.py tests/test_layers.py
CORE_VENV := .venv-core

test-core: ## `pip install .` (numpy + h5py only) in a fresh venv; the runtime's tests there
	rm -rf $(CORE_VENV) && $(PYTHON) -m venv $(CORE_VENV)
	$(CORE_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(CORE_VENV)/bin/python -m pip install --quiet . 'pytest>=9' pytest-timeout
	@echo "core install: $$(du -sh $(CORE_VENV)/lib/python*/site-packages | cut -f1) of site-packages"
	@# -P: import the installed package, not the source tree
	OPENBLAS_NUM_THREADS=1 $(CORE_VENV)/bin/python -P -m pytest -q -p no:cacheprovider $(CORE_TESTS)

# Every optional extra installed by itself (the list: .ci/extras.py --list), each in a
# fresh venv sharing nothing but pip's cache and one built wheel of shtools.
EXTRAS     ?= $(shell $(PYTHON) .ci/extras.py --list)
EXTRA_VENV := .venv-extra

test-extras: ## Each extra alone in a fresh venv: the modules it promises import and run
	rm -rf $(EXTRA_VENV) build/extras-wheel build/extras-src && mkdir -p build/extras-src
	@# the wheel from a copy of the package alone: setuptools' package search would walk the venvs
	cp -r pyproject.toml README.md shtools build/extras-src/
	$(PYTHON) -m pip wheel --quiet --no-deps --wheel-dir build/extras-wheel build/extras-src
	@set -e; wheel=$$(ls $(CURDIR)/build/extras-wheel/shtools-*.whl); \
	for extra in $(EXTRAS); do \
	  start=$$(date +%s); \
	  rm -rf $(EXTRA_VENV) && $(PYTHON) -m venv $(EXTRA_VENV); \
	  $(EXTRA_VENV)/bin/python -m pip install --quiet --no-compile "$$wheel[$$extra]"; \
	  (cd $(EXTRA_VENV) && OPENBLAS_NUM_THREADS=1 bin/python -P $(CURDIR)/.ci/extras.py $$extra); \
	  echo "  $$extra: $$(( $$(date +%s) - start )) s"; \
	done
	rm -rf $(EXTRA_VENV) build/extras-wheel build/extras-src

bench: $(STAMP) ## Run every benchmarks/bench_*.py, print their tables, write benchmarks/RESULTS.md (QUICK=1: short; ONLY="look relight": re-run these, keep the other rows)
	OPENBLAS_NUM_THREADS=1 $(PY) -m benchmarks $(if $(QUICK),--quick) $(if $(ONLY),--update $(foreach n,$(ONLY),-k $(n)))

golden: $(STAMP) ## Regenerate tests/golden/golden.h5 on purpose (review with shtools diff)
	OPENBLAS_NUM_THREADS=1 $(PY) tests/golden/regenerate.py

examples: $(STAMP) ## Build the example asset pipeline in examples/ (make -j2 works)
	$(MAKE) -C examples

lint: $(STAMP) ## ruff check
	$(VENV)/bin/ruff check shtools tests benchmarks

clean: ## Remove the venv, outputs and caches
	rm -rf $(VENV) $(CORE_VENV) $(EXTRA_VENV) $(OUT) .pytest_cache build *.egg-info
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
