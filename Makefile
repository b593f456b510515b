# Two commands do everything on a fresh machine with Python >= 3.11 and make:
#   make demo   - create .venv, install, run the main job on the built-in problems
#   make test   - create .venv if needed, install, run the test suite
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
# Single-threaded BLAS: the matrices here are small to medium, and on a shared 2-core machine
# threaded BLAS was measured up to 10x slower (oversubscription). Override on the command line.
BLAS_THREADS ?= 1
# The suite runs one test file per worker (module fixtures are built once); at most 4 workers,
# as each holds its own models and solvers in memory. TEST_WORKERS=0 runs it in one process.
TEST_WORKERS ?= $(shell $(PYTHON) -c "import os; print(min(4, len(os.sched_getaffinity(0))))" 2>/dev/null || echo 2)
RUN    := OPENBLAS_NUM_THREADS=$(BLAS_THREADS) OMP_NUM_THREADS=$(BLAS_THREADS) MKL_NUM_THREADS=$(BLAS_THREADS)

.PHONY: demo test test-slow lint format bench clean install

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(RUN) $(BIN)/wingopt demo

test: $(STAMP)
	$(RUN) $(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile

test-slow: $(STAMP)
	$(RUN) $(BIN)/python -m pytest -m slow

lint: $(STAMP)
	$(BIN)/ruff check wingopt tests examples benchmarks
	$(BIN)/ruff format --check wingopt tests examples benchmarks

format: $(STAMP)
	$(BIN)/ruff format wingopt tests examples benchmarks
	$(BIN)/ruff check --fix wingopt tests examples benchmarks

bench: $(STAMP)
	for f in benchmarks/bench_*.py; do $(RUN) $(BIN)/python $$f || exit 1; done

clean:
	rm -rf $(VENV) wingopt-demo .pytest_cache .ruff_cache *.egg-info
