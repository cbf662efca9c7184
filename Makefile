# Every target sets up .venv itself when it is missing or pyproject.toml changed.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: run test test-slow lint format bench paper docs clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -e '.[dev]'
	touch $(STAMP)

run: $(STAMP)
	$(PY) experiments/run.py

# Both cores: a test file per worker (module fixtures are built once, as without xdist).
test: $(STAMP)
	$(PY) -m pytest -q -m "not slow" -n 2 --dist loadfile --durations=15

# With XLA's optimisations (tests/conftest.py): learning tests run long enough that they pay.
test-slow: $(STAMP)
	JAX_DISABLE_MOST_OPTIMIZATIONS=0 $(PY) -m pytest -q -m "slow"

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

format: $(STAMP)
	$(VENV)/bin/ruff check --fix .
	$(VENV)/bin/ruff format .

bench: $(STAMP)
	$(PY) -m bench.bench $(BENCH_ARGS)

# The paper's results into experiments/results/ (REPORT.md there): CartPole, inverted_pendulum and a
# short halfcheetah run on CPU; SCALE=cpu-full for every MuJoCo result at 1M env steps per
# run (hours; cached and resumed), SCALE=paper for the paper's episode budgets (a GPU's).
# Training runs are kept in experiments/results/runs/ and reused; a finished MuJoCo run also
# leaves a record in experiments/results/records/ (committed), reused where the run is gone.
SCALE ?= cpu
paper: $(STAMP)
	$(PY) -m experiments.paper.all --scale $(SCALE)

# The documentation site into site/ (strict: a broken link or a missing page fails it).
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache site
