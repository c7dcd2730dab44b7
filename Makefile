# Every target sets itself up: a .venv built from pyproject.toml, at the exact
# versions of constraints.txt (a run repeats to the last bit only with them).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
export MPLBACKEND := Agg
export JAX_PLATFORMS := cpu
# Bytecode is written (under the repository and .venv, ignored by git) so that every
# process after the first reads it: where PYTHONDONTWRITEBYTECODE is set (this machine
# kind sets it), every process would compile the package's sources again, and every
# pytest worker its tests (a warm `piecs-bayes fit` 1.15-1.37 s against 1.03-1.11 s;
# collecting the tests 11.6 s against 5.4 s, in each of the two workers).
unexport PYTHONDONTWRITEBYTECODE

.PHONY: demo test test-slow test-all lint lint-imports clean venv conformance workers

venv: $(STAMP)

# The packages go in with uv (from PyPI into the new .venv) where it can be had, pip
# otherwise: the same versions (constraints.txt), byte-compiled as pip does, in 28 s
# against pip's 67 s on this 2-core kind of machine (issue 39: the environment is part of
# what `.ci/run` costs). If uv cannot be installed or fails, pip installs everything.
$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	{ $(BIN)/python -m pip install --quiet -c constraints.txt uv && \
	  $(BIN)/uv pip install --python $(BIN)/python --quiet --compile-bytecode \
	    -c constraints.txt -e ".[test,dask,notebooks]"; } || { \
	  $(BIN)/python -m pip install --quiet --upgrade pip && \
	  $(BIN)/python -m pip install --quiet -c constraints.txt -e ".[test,dask,notebooks]"; }
	$(BIN)/python -m compileall -q piecs_bayes >/dev/null  # the editable package's bytecode
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/piecs-bayes demo data/demo/study.toml --out reports/demo

# One worker per usable core, each with one BLAS thread: OpenBLAS's own threads spin
# while they wait, and two workers' worth of them on two cores cost a quarter of the
# heaviest tests' time (72 s against 54 s for the coverage, batch and feedback tests
# on this 2-core kind of machine). The suite is work for the processor (compiling and
# running programs: 1.93 of 2 cores busy through a cold run), so it shortens with the
# cores; a worker peaks at 2.6 GiB, so no more workers than memory holds at 3 GiB
# each. `make test WORKERS=N` chooses. Work stealing: a worker that runs dry takes
# tests queued on another, so a long test late in one queue leaves no core idle at
# the end (300 s of pytest against 322-336 s with the default `load`)
WORKERS ?= $(shell $(PYTHON) -c 'import os; \
  cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(); \
  mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"); \
  print(max(1, min(cores or 1, mem // (3 << 30))))' 2>/dev/null || echo 2)
# Two tiers. `make test`: every behaviour, the statistical checks at sizes whose power
# each test states (a 300-part coverage check, its window 3 binomial sds). `make
# test-all` adds the full-power tier: the tests marked slow (the 1,000-part coverage
# checks, the notebooks executed end to end), then the golden and regeneration tests
# again under XLA compiling for other instruction sets (.ci/isa-reruns).
test: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -q -n $(WORKERS) --dist worksteal -m "not slow"

test-slow: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(BIN)/python -m pytest -q -n $(WORKERS) --dist worksteal -m slow
	bash .ci/isa-reruns

test-all: test test-slow

# The worker count the test tiers use here (benchmarks/bench_first_contact.py runs the
# suite with it).
workers:
	@echo $(WORKERS)

# Peer agreement with LinuxCNC's rs274 (Debian package linuxcnc-uspace): installs
# it when missing, then runs the tests marked rs274 (they fail here if it is absent).
conformance: $(STAMP)
	@command -v rs274 >/dev/null || { \
	  SUDO=$$([ "$$(id -u)" = 0 ] || echo sudo); \
	  $$SUDO apt-get update && $$SUDO apt-get install -y linuxcnc-uspace; }
	@command -v rs274 >/dev/null || { echo "rs274 is still not installed" >&2; exit 1; }
	$(BIN)/python -m pytest -q -m rs274 tests/gcode/test_gcode_rs274.py tests/cli/test_gcode_cli.py

lint: $(STAMP)
	$(BIN)/ruff check piecs_bayes tests
	$(BIN)/ruff format --check piecs_bayes tests
	$(BIN)/lint-imports

# The layers contract ([tool.importlinter] in pyproject.toml) on its own.
lint-imports: $(STAMP)
	$(BIN)/lint-imports

clean:
	rm -rf $(VENV) reports/demo .pytest_cache .import_linter_cache
