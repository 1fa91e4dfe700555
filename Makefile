# dpc_mjx: every target installs the project into .venv first if needed, with the exact versions
# of constraints.txt; `make test-latest` tests the newest releases pyproject.toml allows instead,
# `make test-mujoco3` the pins with MuJoCo 3.17.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-test
BENCH_STAMP := $(VENV)/.installed-bench
DOCS_STAMP := $(VENV)/.installed-docs
LATEST := .venv-latest
EXTRAS := test,render,urdf,onnx
# The other MuJoCo the whole suite runs on (`make test-mujoco3`): the pins of constraints.txt with
# this mujoco in place of the pinned one (mujoco-mjx 3.17.0 either way), in its own venv.
MUJOCO3 := 3.17.0
MUJOCO3_VENV := .venv-mujoco3

.PHONY: install render-deps demo test test-all test-latest test-mujoco3 bench mjcf docs lint clean

# MuJoCo 4 is three wheels (mujoco-core, mujoco-studio, mujoco), and pip upgrading a MuJoCo 3 in
# place deletes the new core's files (`import mujoco`: "core bindings ('mujoco-core') are
# missing"): so a MuJoCo 3 in venv $(1) (mujoco without mujoco-core) is uninstalled first.
define drop_mujoco3
	if $(1)/bin/python -m pip show -q mujoco 2>/dev/null && \
	  ! $(1)/bin/python -m pip show -q mujoco-core 2>/dev/null; then \
	  echo "$(1): uninstalling MuJoCo 3 before MuJoCo 4 (docs/commands.md, \"Install\")"; \
	  $(1)/bin/python -m pip uninstall -q -y mujoco; fi
endef

$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(call drop_mujoco3,$(VENV))
	$(BIN)/python -m pip install -q -c constraints.txt -e ".[$(EXTRAS)]"
	touch $(STAMP)

$(BENCH_STAMP): $(STAMP)
	$(BIN)/python -m pip install -q -c constraints.txt -e ".[$(EXTRAS),bench]"
	touch $(BENCH_STAMP)

install: $(STAMP) render-deps

# Headless rendering (dpc-mjx render; a test renders a clip) needs OSMesa, Debian's libosmesa6:
# installed here when it is missing and we are root with apt-get, else we say what to install.
render-deps:
	@if ldconfig -p | grep -q libOSMesa; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	  echo "installing libosmesa6 (headless rendering)"; \
	  apt-get install -y -q libosmesa6 >/dev/null 2>&1 || \
	  (apt-get update -q >/dev/null 2>&1 && apt-get install -y -q libosmesa6 >/dev/null 2>&1); \
	else echo "dpc-mjx render needs OSMesa: sudo apt-get install libosmesa6 (Debian/Ubuntu)"; fi

# The main job on a small default (see README).
demo: $(STAMP)
	$(BIN)/dpc-mjx demo

# Two workers, one test file each at a time (module fixtures share their compiles), the files in
# the order tests/conftest.py gives them (longest first; xdist would otherwise reorder them by
# test count and leave the long few-test files to the end); the JAX compilation cache in
# .cache/jax (tests/conftest.py) serves repeated compiles, and XLA's older fusion emitters and
# LLVM -O1 (set by `import dpc_mjx` on jaxlib 0.9.2 when XLA_FLAGS is unset:
# dpc_mjx/xla_flags.py) compile about half as long.
PYTEST_ARGS := -q -n 2 --dist loadfile --no-loadscope-reorder
PYTEST := $(BIN)/python -m pytest $(PYTEST_ARGS)

test: $(STAMP) render-deps
	$(PYTEST)

# Also the tests marked slow: every task x every arm (tests/test_matrix.py) and the paper's
# alternate arms stepped in tests/test_tasks.py (about half an hour on 2 cores).
test-all: $(STAMP) render-deps
	$(PYTEST) -m "slow or not slow"

# The same tests in a second venv with the newest releases pyproject.toml allows (no
# constraints; every run upgrades, so a new release of jax, flax, brax ... is picked up), with
# its own compilation cache.
LATEST_VERSIONS := jax jaxlib flax optax mujoco mujoco-mjx brax

test-latest: render-deps
	test -x $(LATEST)/bin/python || $(PYTHON) -m venv $(LATEST)
	$(LATEST)/bin/python -m pip install -q --upgrade pip
	$(call drop_mujoco3,$(LATEST))
	$(LATEST)/bin/python -m pip install -q --upgrade --upgrade-strategy eager -e ".[$(EXTRAS)]"
	@$(LATEST)/bin/python -c "import sys; from importlib.metadata import version; \
	  print('latest:', ', '.join(p + ' ' + version(p) for p in sys.argv[1:]))" $(LATEST_VERSIONS)
	DPC_JAX_CACHE=$(CURDIR)/.cache/jax-latest $(LATEST)/bin/python -m pytest $(PYTEST_ARGS)

# The same tests on MuJoCo $(MUJOCO3), in a venv of its own made fresh (MuJoCo 3 and 4 do not
# replace each other cleanly in place), with the compilation cache of `make test` (the jax is
# the same; a program is keyed by its HLO, so a model that compiles differently is a new entry).
$(MUJOCO3_VENV)/.installed-test: pyproject.toml constraints.txt
	rm -rf $(MUJOCO3_VENV) && $(PYTHON) -m venv $(MUJOCO3_VENV)
	sed 's/^mujoco==.*/mujoco==$(MUJOCO3)/' constraints.txt > $(MUJOCO3_VENV)/constraints.txt
	$(MUJOCO3_VENV)/bin/python -m pip install -q --upgrade pip
	$(MUJOCO3_VENV)/bin/python -m pip install -q -c $(MUJOCO3_VENV)/constraints.txt -e ".[$(EXTRAS)]"
	touch $@

test-mujoco3: $(MUJOCO3_VENV)/.installed-test render-deps
	@$(MUJOCO3_VENV)/bin/python -c "from importlib.metadata import version as v; \
	  print('mujoco', v('mujoco'), '+ mujoco-mjx', v('mujoco-mjx'))"
	$(MUJOCO3_VENV)/bin/python -m pytest $(PYTEST_ARGS)

bench: $(BENCH_STAMP)
	$(BIN)/python experiments/bench_physics.py
	$(BIN)/python experiments/bench_qp.py
	$(BIN)/python experiments/bench_controller.py
	$(BIN)/python experiments/bench_env.py
	$(BIN)/python experiments/bench_engines.py
	$(BIN)/python experiments/bench_deploy.py
	$(BIN)/python experiments/bench_limit.py
	$(BIN)/python experiments/bench_callback.py
	$(BIN)/python experiments/bench_compile.py

mjcf: $(STAMP)
	$(BIN)/dpc-mjx mjcf mjcf

# The documentation site (mkdocs.yml): docs/*.md and the API reference generated from the
# docstrings (griffe reads the source, nothing runs), built strictly into site/: a warning, a
# broken link, anchor or cross-reference fails. NO_MKDOCS_2_WARNING: mkdocs-material's notice.
$(DOCS_STAMP): $(STAMP)
	$(BIN)/python -m pip install -q -c constraints.txt -e ".[$(EXTRAS),docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --clean --site-dir site

# ruff, then the layers of docs/architecture.md ("The layers") (import-linter's contract in pyproject.toml)
lint: $(STAMP)
	$(BIN)/ruff check dpc_mjx tests experiments
	$(BIN)/lint-imports --no-logo --cache-dir .cache/import-linter

clean:
	rm -rf $(VENV) $(LATEST) $(MUJOCO3_VENV) .cache
