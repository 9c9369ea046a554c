# One entry point for a fresh machine: `make demo` runs the main job, `make test` runs every check,
# `make check` the quick ones (no docs, no tests marked slow), `make docs` builds the API
# reference and the walkthroughs (docs/_build/html/index.html).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
TASK ?= coaster
OUT ?= demo-output

.PHONY: demo test check docs lint bench clean system-deps

# Debian packages for headless rendering (EGL, with OSMesa as fallback), and the chromium the
# browser test of `pbdkit view` drives (playwright's own browser download is not used); skipped
# when not root.
SYSTEM_PKGS := libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 chromium
system-deps:
	@if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	  missing=$$(for p in $(SYSTEM_PKGS); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	  if [ -n "$$missing" ]; then apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing; fi; \
	else echo "system-deps: not root or no apt-get; install $(SYSTEM_PKGS) yourself"; fi

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): pyproject.toml | $(BIN)/python system-deps
	$(BIN)/python -m pip install --quiet -e ".[sim,view,test,docs]"
	touch $(STAMP)

# The tests also speak ROS 2 (the ros extra: PyPI's ROS 2 wheels); `make demo` does not need it.
ROS_STAMP := $(VENV)/.installed-ros
$(ROS_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[sim,view,test,docs,ros]"
	touch $(ROS_STAMP)

demo: $(STAMP)
	$(BIN)/pbdkit demo --out $(OUT)

# Warnings are errors (a broken docstring or reference fails), -E rereads every page (an
# incremental build would not repeat the warnings of pages it does not reread), offline.
SPHINX := $(BIN)/python -m sphinx -E -W --keep-going -q -b html docs docs/_build/html

lint: $(ROS_STAMP)
	$(BIN)/ruff check src tests benchmarks examples docs
	$(BIN)/ruff format --check src tests benchmarks examples docs
	$(BIN)/mypy

test: lint
	$(SPHINX)
	$(BIN)/python -m pytest -q

# The quick loop before a commit (about a minute): `make test` without the docs and the tests
# marked slow (pyproject.toml's pytest markers). The same prerequisites: nothing more to install.
check: lint
	$(BIN)/python -m pytest -q -m "not slow"

docs: $(STAMP)
	$(SPHINX)
	@echo "open docs/_build/html/index.html"

bench: $(STAMP)
	$(BIN)/python benchmarks/run_all.py

clean:
	rm -rf $(VENV) build *.egg-info src/*.egg-info .pytest_cache .mypy_cache .ruff_cache \
	  docs/_build docs/api/generated
