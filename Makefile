# gpis-harness: set-up, tests and the pictures of the scene library.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup eval eval-quick test test-all scenes bench clean

setup: $(STAMP)

# Reinstall only when the package metadata changed (editable install covers code).
# uv (from PyPI, into the venv) installs the dependencies in about 30 s where pip takes
# about a minute; if uv cannot be installed or fails (a network only pip is configured
# for, say), pip does the same install. Both compile the bytecode at install time, so
# no process (each test subprocess, each worker) compiles the libraries as it starts.
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	{ $(BIN)/python -m pip install --quiet 'uv>=0.5,<1' \
	  && $(BIN)/python -m uv pip install --quiet --compile-bytecode --python $(BIN)/python -e '.[dev,cluster]'; } \
	|| { $(BIN)/python -m pip install --quiet --upgrade pip \
	  && $(BIN)/python -m pip install --quiet -e '.[dev,cluster]'; }
	touch $(STAMP)

eval: setup
	$(BIN)/gpis-harness eval experiments/default.toml

eval-quick: setup
	$(BIN)/gpis-harness eval experiments/quick.toml

test: setup
	$(BIN)/python -m pytest -q

test-all: setup
	$(BIN)/python -m pytest -q --runslow

scenes: setup
	$(BIN)/gpis-harness scenes render --out results/scenes

bench: setup
	$(BIN)/gpis-harness bench all

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis results/scenes results/default results/quick
