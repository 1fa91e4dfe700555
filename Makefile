# dpc_mjx: every target installs the project into .venv first if needed.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-test
BENCH_STAMP := $(VENV)/.installed-bench

.PHONY: install demo test test-all bench mjcf lint clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e ".[test]"
	touch $(STAMP)

$(BENCH_STAMP): $(STAMP)
	$(BIN)/python -m pip install -q -e ".[test,bench]"
	touch $(BENCH_STAMP)

install: $(STAMP)

# The main job on a small default (see README).
demo: $(STAMP)
	$(BIN)/dpc-mjx demo

# Two workers, one test file each at a time (module fixtures share their compiles); the JAX
# compilation cache in .cache/jax (tests/conftest.py) serves repeated compiles.
PYTEST := $(BIN)/python -m pytest -q -n 2 --dist loadfile

test: $(STAMP)
	$(PYTEST)

# Also the tests marked slow: every task x every arm (tests/test_matrix.py) and the paper's
# alternate arms stepped in tests/test_tasks.py (about half an hour on 2 cores).
test-all: $(STAMP)
	$(PYTEST) -m "slow or not slow"

bench: $(BENCH_STAMP)
	$(BIN)/python experiments/bench_physics.py
	$(BIN)/python experiments/bench_qp.py
	$(BIN)/python experiments/bench_controller.py
	$(BIN)/python experiments/bench_env.py

mjcf: $(STAMP)
	$(BIN)/dpc-mjx mjcf mjcf

lint: $(STAMP)
	$(BIN)/ruff check dpc_mjx tests experiments

clean:
	rm -rf $(VENV) .cache
