# Set-up and the two main jobs. Each target creates the virtual environment
# when it is missing and installs the project into it.
#
#   make bench   quick benchmark matrix; tables under results/quick/
#   make test    the test suite
#
# torch is installed first, pinned, so that pip does not pull a CUDA build:
#   make test TORCH=torch==2.5.1
#   make test TORCH_INDEX="--index-url https://download.pytorch.org/whl/cpu"

PYTHON ?= python3
VENV ?= .venv
TORCH ?= torch==2.13.0
TORCH_INDEX ?=
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: bench test benchmark paper leaderboard gpu-figures gpu-prepare clean-venv

# pip byte-compiles what it installs one file after another; compileall does the same files on every core
# (a file written for another Python version, such as one of torch's tests, is skipped, as pip skips it)
$(STAMP): pyproject.toml Makefile
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --no-compile $(TORCH_INDEX) "$(TORCH)"
	$(BIN)/python -m pip install --quiet --no-compile -e ".[test,sr]"
	$(BIN)/python -m compileall -qq -j 0 $(VENV)/lib || true
	touch $(STAMP)

bench: $(STAMP)
	$(BIN)/python -m bench run --systems double_pendulum --n-seeds 3 --budget 10 --out results/quick

# the default tests on every core (pytest-xdist); each test process pins one BLAS and torch thread, and
# the tests that compile with torch.compile share one process (their xdist_group), so the compiler starts once
test: $(STAMP)
	$(BIN)/python -m pytest -n auto --dist loadgroup

benchmark: $(STAMP)
	$(BIN)/python -m pytest tests/benchmarks -m benchmark --benchmark-only --benchmark-columns=min,mean,median,rounds

# The published double pendulum tables: every method, 10 seeds, 60 s per run; SyReNets in the
# configuration that reaches the paper's accuracy soonest (python -m bench list names it).
paper: $(STAMP)
	$(BIN)/python -m bench run --systems double_pendulum --n-seeds 10 --budget 60 --workers 2 --config syrenets=best-300s --out results/paper/double_pendulum_60s

# The leaderboard (results/README.md, from the records in results/leaderboard): every system and method, both
# experiments where they apply, 10 seeds. About 870 runs: at 8 s each plus
# evaluation and rollout (about 2 s a run on average), about an hour on
# 2 cores (the 7-DoF arms take 16 of those minutes).
LEADERBOARD_BUDGET ?= 8
# the hybrids (the identified rigid body plus a learned residual) on the measured arm
LEADERBOARD_HYBRIDS ?= standard+gp,feasible+gp,standard+mlp,feasible+delan
leaderboard: $(STAMP)
	$(BIN)/python -m bench run --systems all --n-seeds 10 --budget $(LEADERBOARD_BUDGET) --workers 2 --out results/leaderboard
	$(BIN)/python -m bench run --systems kuka_lwr4 --methods $(LEADERBOARD_HYBRIDS) --n-seeds 10 --budget $(LEADERBOARD_BUDGET) --workers 2 --out results/leaderboard
	$(BIN)/python -m bench leaderboard results/leaderboard --commentary results/commentary.md --out results/README.md
	$(BIN)/python -m bench index

# The GPU figures of stacked seeds (results/harness/gpu.md), on a machine with CUDA:
#   make gpu-figures
# For a bare GPU machine without Pinocchio or network: make gpu-prepare here, carry gpu_data/ and .whl/ there,
# and run the line it prints.
gpu-figures: $(STAMP)
	$(BIN)/python -m bench study gpu --device cuda --data gpu_data

gpu-prepare: $(STAMP)
	$(BIN)/python -m bench study gpu --prepare gpu_data
	$(BIN)/python -m pip download --quiet --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
		--platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d .whl \
		$$($(BIN)/python -c "from bench.studies.gpu_figures import WHEELS; print(*WHEELS)")
	$(BIN)/python -m bench study gpu --dry-run --data gpu_data

clean-venv:
	rm -rf $(VENV)
