# gpis-harness: set-up, tests and the pictures of the scene library.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: setup eval eval-quick benchmark test test-all scenes bench clean

setup: $(STAMP)

# Reinstall only when the package metadata or the constraints changed (editable install
# covers code). constraints.txt pins every package to the exact version that made
# results/reference (pyproject.toml's ranges say what is compatible, the constraints what
# is reproduced), for uv itself too; both installers honour it.
# uv (from PyPI, into the venv) installs the dependencies in seconds where pip takes
# about a minute; if uv cannot be installed or fails (a network only pip is configured
# for, say), pip does the same install. The bytecode is compiled at install time, so no
# process (each test subprocess, each worker) compiles the libraries as it starts (with
# PYTHONDONTWRITEBYTECODE set, as on this machine, each would, every time). After uv,
# compileall skips what no process here imports (the libraries' own test suites, pip,
# setuptools, pybullet's example environments): 12 s instead of 22 s for everything.
NOCOMPILE := /(tests?|pip|setuptools|pybullet_envs|pybullet_examples|pybullet_robots|pybullet_utils)/
$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	{ $(BIN)/python -m pip install --quiet -c constraints.txt 'uv>=0.5,<1' \
	  && $(BIN)/python -m uv pip install --quiet --python $(BIN)/python -c constraints.txt -e '.[dev,cluster]' \
	  && { $(BIN)/python -m compileall -q -j 0 -x '$(NOCOMPILE)' $(VENV)/lib > /dev/null || true; }; } \
	|| { $(BIN)/python -m pip install --quiet --upgrade pip \
	  && $(BIN)/python -m pip install --quiet -c constraints.txt -e '.[dev,cluster]'; }
	touch $(STAMP)

eval: setup
	$(BIN)/gpis-harness eval experiments/default.toml

eval-quick: setup
	$(BIN)/gpis-harness eval experiments/quick.toml

# The benchmark's three tiers (docs/benchmark.md), each its own resumable run in
# results/benchmark-TIER with its leaderboard; about 31 minutes on this 2-core machine
# (easy 4, standard 9, hard 18; measured 2026-11-26 on a clean clone).
benchmark: setup
	$(BIN)/gpis-harness eval experiments/benchmark-easy.toml
	$(BIN)/gpis-harness eval experiments/benchmark-standard.toml
	$(BIN)/gpis-harness eval experiments/benchmark-hard.toml

# Test files run in parallel on up to 4 processes (pytest-xdist; one per core here): each
# file on one process, so its module fixtures are built once. On this 2-core machine the
# suite took 319 s this way against about 555 s in one process (2026-11-25).
PYTEST := $(BIN)/python -m pytest -q -n auto --maxprocesses 4 --dist loadfile

test: setup
	$(PYTEST)

test-all: setup
	$(PYTEST) --runslow

scenes: setup
	$(BIN)/gpis-harness scenes render --out results/scenes

bench: setup
	$(BIN)/gpis-harness bench all

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis results/scenes results/default results/quick results/benchmark-*
