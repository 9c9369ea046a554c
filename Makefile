# One entry point for a fresh machine: `make demo` runs the main job (installing only what it
# needs: the library and the simulator), `make test` installs the test, docs, view and ROS 2
# tools and runs every check, `make check` the quick ones (no docs, no tests marked slow),
# `make docs` builds the API reference and the walkthroughs (docs/_build/html/index.html),
# `make wheel` builds the library's wheel into dist/.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
DEMO_STAMP := $(VENV)/.installed-demo
STAMP := $(VENV)/.installed
TASK ?= coaster
OUT ?= demo-output

.PHONY: demo test check docs lint bench wheel clean demo-system-deps system-deps

# Debian packages for headless rendering (EGL, with OSMesa as fallback): the demo's; and the
# chromium the browser test of `pbdkit view` drives (playwright's own browser download is not
# used): the tests'. Skipped when not root.
DEMO_PKGS := libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6
TEST_PKGS := $(DEMO_PKGS) chromium
define apt_install
	@if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	  missing=$$(for p in $(1); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	  if [ -n "$$missing" ]; then echo "installing Debian packages: $$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing; fi; \
	else echo "not root or no apt-get: install $(1) yourself"; fi
endef
demo-system-deps:
	$(call apt_install,$(DEMO_PKGS))
system-deps:
	$(call apt_install,$(TEST_PKGS))

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# The demo's install: the library and the simulator extra, with pip's progress shown.
$(DEMO_STAMP): pyproject.toml | $(BIN)/python demo-system-deps
	@echo "installing pbdkit and the simulator into $(VENV) (a few minutes the first time)"
	$(BIN)/python -m pip install --progress-bar on -e ".[sim]"
	touch $(DEMO_STAMP)

$(STAMP): pyproject.toml $(DEMO_STAMP) | system-deps
	@echo "installing the test, docs and view tools into $(VENV)"
	$(BIN)/python -m pip install --progress-bar on -e ".[sim,view,test,docs]"
	touch $(STAMP)

# The tests also speak ROS 2 (the ros extra: PyPI's ROS 2 wheels); `make demo` does not need it.
ROS_STAMP := $(VENV)/.installed-ros
$(ROS_STAMP): $(STAMP)
	@echo "installing the ROS 2 wheels into $(VENV)"
	$(BIN)/python -m pip install --progress-bar on -e ".[sim,view,test,docs,ros]"
	touch $(ROS_STAMP)

demo: $(DEMO_STAMP)
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

# The library's wheel (dist/pbdkit-*.whl): `pip install dist/pbdkit-*.whl` installs the library
# alone; its extras are named as with -e: 'pbdkit-...whl[sim]'.
wheel: | $(BIN)/python
	$(BIN)/python -m pip wheel --no-deps --wheel-dir dist .

clean:
	rm -rf $(VENV) build dist *.egg-info src/*.egg-info .pytest_cache .mypy_cache .ruff_cache \
	  docs/_build docs/api/generated
