# dpc_mjx: every target installs the project into .venv first if needed.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-test
BENCH_STAMP := $(VENV)/.installed-bench

.PHONY: install demo test bench mjcf lint clean

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

test: $(STAMP)
	$(BIN)/python -m pytest -q

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
