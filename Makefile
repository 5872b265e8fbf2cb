# Two entry points on a fresh machine (only Python >= 3.11 needed):
#   make demo   -> builds .venv, installs dischargelab, runs the demo into ./demo-out/
#   make test   -> same .venv (with the docs and PyBaMM extras), runs the whole test suite
# Checks CI runs too: make docs (the documentation site), make lint (ruff), make typecheck
# (mypy on the public API), make min-versions (the suite with every dependency at its
# declared lower bound).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test lint typecheck docs min-versions bench browser lua postgres mdbtools clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[all,test]"
	touch $(STAMP)

# The docs extra (Sphinx and its extensions): `make docs` builds the site with it, and the
# suite's site test (tests/test_docs.py) builds it too, so `make test` installs it as well.
DOCS_STAMP := $(VENV)/.docs-installed

$(DOCS_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[docs]"
	touch $(DOCS_STAMP)

# PyBaMM (the virtual extra), at test time only: the suite's PyBaMM lives (tests/pybamm_life.py)
# check capacity today's band on physics the estimators were not built from.
PYBAMM_STAMP := $(VENV)/.pybamm-installed

$(PYBAMM_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[virtual]"
	touch $(PYBAMM_STAMP)

demo: $(STAMP)
	$(BIN)/dischargelab demo --out demo-out --force

# the sources byte-compiled first: the suite starts many Python processes (commands, servers,
# Dask workers), and where PYTHONDONTWRITEBYTECODE is set each would compile them again
# (the docs extra too: the site test builds the documentation; no test is skipped for want of it)
# (one BLAS thread, as the command line takes: the suite's matrices are small, and threads
# only wait for one another on a shared machine)
test: $(DOCS_STAMP) $(PYBAMM_STAMP) browser lua postgres mdbtools
	$(BIN)/python -m compileall -q src
	OPENBLAS_NUM_THREADS=$${OPENBLAS_NUM_THREADS:-1} $(BIN)/python -m pytest

lint: $(STAMP)
	$(BIN)/ruff check src tests benchmarks examples

# The public API; api.py is included once it exists.
typecheck: $(STAMP)
	$(BIN)/mypy src/dischargelab/__init__.py $(wildcard src/dischargelab/api.py)

# The documentation site (Sphinx: docs/*.md, the API reference from the numpydoc docstrings,
# the gallery made by running examples/, the guides' example commands run on the example set)
# into docs/_build/html, offline, warnings as errors.
docs: $(DOCS_STAMP)
	rm -rf docs/_build docs/generated docs/gallery docs/sg_execution_times.rst
	$(BIN)/python -m sphinx -W --keep-going -q -b html -j 1 docs docs/_build/html
	@echo "documentation: docs/_build/html/index.html"

# A separate venv (.venv/min-versions) with the lower bounds from pyproject.toml.
min-versions:
	PYTHON=$(PYTHON) bash .ci/min-versions.sh

# The HTML report and the web pages are checked in headless Chromium, driven by Selenium
# through Debian's chromedriver (same package version; nothing is downloaded). Installed from
# Debian's packages when missing and we may (root with apt-get); otherwise those tests are
# skipped (outside CI) with a note.
browser:
	@{ command -v chromium >/dev/null 2>&1 && command -v chromedriver >/dev/null 2>&1; } || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing chromium and chromium-driver (headless browser for the page tests)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium \
	      chromium-driver >/dev/null; \
	  else echo "note: chromium/chromedriver not found; the browser tests will be skipped"; fi; }

# The on-board script tests run the generated ArduPilot script in Debian's Lua 5.3 (ArduPilot's
# Lua is 5.3.6) and check it with luacheck: installed when missing and we may.
lua:
	@{ command -v lua5.3 >/dev/null 2>&1 && command -v luacheck >/dev/null 2>&1; } || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing lua5.3 and lua-check (the on-board script tests)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq lua5.3 \
	      lua-check >/dev/null; \
	  else echo "note: lua5.3/luacheck not found; the on-board script tests will be skipped"; fi; }

# The logbook tests also run against a throwaway PostgreSQL cluster (initdb + pg_ctl as the
# `postgres` user, on 127.0.0.1): Debian's server package is installed when missing and we may.
postgres:
	@ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing postgresql (throwaway server for the logbook tests)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq postgresql >/dev/null; \
	  else echo "note: postgresql not found; the logbook's PostgreSQL tests will be skipped"; fi; }

# Arbin .res files are MS Access databases, read through Debian's mdbtools (mdb-export):
# installed when missing and we may; otherwise the .res tests are skipped (outside CI).
mdbtools:
	@command -v mdb-export >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing mdbtools (reader of Arbin .res files)"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq mdbtools >/dev/null; \
	  else echo "note: mdbtools not found; the Arbin .res tests will be skipped"; fi; }

bench: $(STAMP)
	$(BIN)/python benchmarks/fit_speed.py
	$(BIN)/python benchmarks/fit_latency.py
	$(BIN)/python benchmarks/slow_to_fast.py
	$(BIN)/python benchmarks/accuracy.py
	$(BIN)/python benchmarks/mission_speed.py
	$(BIN)/python benchmarks/io_read_speed.py
	$(BIN)/python benchmarks/calibration_table1.py
	$(BIN)/python benchmarks/acquire_throughput.py
	$(BIN)/python benchmarks/logbook.py
	$(BIN)/python benchmarks/fleet.py
	$(BIN)/python benchmarks/tester_files.py

clean:
	rm -rf $(VENV) demo-out .pytest_cache .ruff_cache .mypy_cache docs/_build docs/generated docs/gallery
