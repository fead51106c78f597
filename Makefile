# shtools — every target sets itself up: a fresh machine needs only Python 3.11 and make.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed-$(shell cat pyproject.toml | cksum | cut -d' ' -f1)

.DEFAULT_GOAL := help
.PHONY: help demo test bench lint clean

help: ## Show this help
	@grep -E '^[a-zA-Z_-]+:.*?## ' $(MAKEFILE_LIST) | awk 'BEGIN {FS = ":.*?## "}; {printf "  \033[36m%-8s\033[0m %s\n", $$1, $$2}'

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,bench]'
	rm -f $(VENV)/.installed-* && touch $@

demo: $(STAMP) ## Set up and bake the bundled demo scene into out/
	$(PY) -m shtools.demo out

test: $(STAMP) ## Set up and run the whole test suite
	$(PY) -m pytest -n 2 -q

bench: $(STAMP) ## Run the benchmarks and print their tables
	$(PY) -m benchmarks

lint: $(STAMP) ## ruff check
	$(VENV)/bin/ruff check shtools tests benchmarks

clean: ## Remove the venv, outputs and caches
	rm -rf $(VENV) out .pytest_cache build *.egg-info
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
