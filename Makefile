# cappe developer entry points. `make demo` and `make test` work on a fresh machine with Python 3.11 and make.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

# The tests run in parallel, one pytest-xdist worker per core (each worker's BLAS on one thread: tests/conftest.py),
# each test file on one worker so that a module's fixtures are built once, except the files of many independent
# slow cases (SPREAD in tests/conftest.py, whose scheduler `--dist loadgroup` selects): their tests go one by one to
# whichever worker is free. `make test` leaves out the slow
# end-to-end cases marked `extended` (a faster test covers each: see the marker's reason); `make test-slow` runs
# them (before each stop), `make test-all` everything; CI (.ci/run) runs `make test`. `make test TEST_WORKERS=0`
# runs them in this one process.
TEST_WORKERS ?= auto
PYTEST := $(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadgroup

.PHONY: install demo test test-slow test-all check lint typecheck bench clean

install: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

demo: install
	$(BIN)/cappe demo

test: install
	$(PYTEST) -m "not extended"

test-slow: install
	$(PYTEST) -m extended

test-all: install
	$(PYTEST)

lint: install
	$(BIN)/ruff check src tests benchmarks

typecheck: install
	$(BIN)/mypy

check: lint typecheck test

bench: install
	$(BIN)/python -m benchmarks

clean:
	rm -rf $(VENV) build dist .pytest_cache .mypy_cache .ruff_cache
