# pidyn: `make train` runs the default identification, `make test` the test suite.
# Both create .venv and install what they need on first use.
PYTHON ?= python3
# every module of pidyn (and so what they import: torch, lightning, hydra, scipy, pandas), and the
# test runner's; a module that fails to import is left to say so where it is used
define WARM_IMPORTS
import importlib, pkgutil, pidyn
for m in pkgutil.walk_packages(pidyn.__path__, "pidyn."):
    try:
        importlib.import_module(m.name)
    except Exception:
        pass
import matplotlib.pyplot, pytest, tensorboard, xdist
endef
export WARM_IMPORTS
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# torch is pinned to the CPU build; set TORCH_INDEX="--index-url <a CPU wheel index>" where
# the default index would serve a CUDA build.
TORCH_INDEX ?=

.PHONY: install train test test-all docs test-fast lint format bench tb clean-outputs tables tables-smoke generalize diagnose discrepancy-bench discrepancy-bench-building heldout-calibration heldout-calibration-building adequacy-calibration fit-test-calibration basin hayward robustness efficiency benchmarks real

# installed without compiling, then what pidyn and its tests import is compiled once, by importing
# it with bytecode kept (even where the environment asks for none): 15 s on 2 cores, against 28 s
# for compiling all of site-packages, most of which nothing here imports
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q --no-compile "torch==2.13.0" $(TORCH_INDEX)
	$(PY) -m pip install -q --no-compile -e ".[dev]"
	PYTHONDONTWRITEBYTECODE= $(PY) -c "$$WARM_IMPORTS"
	touch $(STAMP)

install: $(STAMP)

train: $(STAMP)
	$(PY) train.py $(ARGS)

# the project's ruff settings (pyproject.toml) before the tests: lint, then the format
lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

format: $(STAMP)
	$(VENV)/bin/ruff check --fix .
	$(VENV)/bin/ruff format .

# the documentation site (mkdocs.yml): the guides and a reference from the docstrings, every
# warning an error (a broken link, a docstring that names a parameter the code does not have)
docs: $(STAMP)
	$(VENV)/bin/mkdocs build --strict -q

# one BLAS/OpenMP thread per test worker: the workers already fill the cores
# one thread a worker (pytest-xdist runs one worker a core), and compiled modules kept between the
# many Python processes a run starts, even where the environment asks for none
TEST_ENV := OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONDONTWRITEBYTECODE=

test: $(STAMP) lint docs
	$(TEST_ENV) $(PY) -m pytest -q -p no:cacheprovider -n auto --dist worksteal --durations=15 -m "not second_proof" $(ARGS)

test-all: $(STAMP) lint docs  # the second end-to-end cases too (about 7 min more on 2 cores)
	$(TEST_ENV) $(PY) -m pytest -q -p no:cacheprovider -n auto --dist worksteal --durations=15 $(ARGS)

test-fast: $(STAMP)
	$(PY) -m pytest -q -m "not slow" $(ARGS)

# the real-records section first (resumable: events already in results/bench_real.csv are kept)
bench: $(STAMP)
	$(PY) experiments/bench_real.py --direction both
	$(PY) experiments/bench.py $(ARGS)

tb: $(STAMP)
	$(PY) -m tensorboard.main --logdir outputs

clean-outputs:
	rm -rf outputs

tables: $(STAMP)
	$(PY) experiments/run_tables.py $(ARGS)

tables-smoke: $(STAMP)
	$(PY) experiments/run_tables.py --smoke $(ARGS)

generalize: $(STAMP)
	$(PY) generalize.py $(ARGS)

diagnose: $(STAMP)
	$(PY) diagnose.py $(ARGS)

discrepancy-bench: $(STAMP)
	$(PY) experiments/discrepancy_bench.py $(ARGS)

discrepancy-bench-building: $(STAMP)
	$(PY) experiments/discrepancy_bench_building.py $(ARGS)

heldout-calibration: $(STAMP)
	$(PY) experiments/heldout_calibration.py $(ARGS)

heldout-calibration-building: $(STAMP)
	$(PY) experiments/heldout_calibration_building.py $(ARGS)

adequacy-calibration: $(STAMP)
	$(PY) experiments/adequacy_calibration.py $(ARGS)

# the second shipped bridge with Painter Street's settings (nothing tuned to it) -> experiments/results/real/hayward.md
hayward: $(STAMP)
	$(PY) train.py experiment=hayward hydra.sweep.dir=outputs/hayward/identify skip_done=true $(ARGS)
	$(PY) experiments/station_table.py outputs/hayward/identify experiments/results/real/hayward --title "Hayward interchange bridge (CSMIP CE58658): every shipped event, identified as Painter Street is"

fit-test-calibration: $(STAMP)
	$(PY) experiments/fit_test_calibration.py $(ARGS)

basin: $(STAMP)
	$(PY) experiments/basin.py --cell duffing $(ARGS)
	$(PY) experiments/basin.py --cell bouc_wen_x1 $(ARGS)
	$(PY) experiments/basin.py --cell bouc_wen_x3 $(ARGS)

robustness: $(STAMP)
	$(PY) experiments/robustness.py $(ARGS)

efficiency: $(STAMP)
	$(PY) experiments/efficiency.py --cell duffing --noise 0.025 $(ARGS)
	$(PY) experiments/efficiency.py --cell bouc_wen_x1 --noise 0.025 $(ARGS)
	$(PY) experiments/efficiency.py --cell bouc_wen_x3 --noise 0.025 $(ARGS)
	$(PY) experiments/efficiency.py --cell bouc_wen_x1_t1.5 --noise 0.025 $(ARGS)
	$(PY) experiments/efficiency.py --cell bouc_wen_x3_t1.5 --noise 0.025 $(ARGS)

benchmarks: $(STAMP)
	$(PY) diagnose.py data=bouc_wen_benchmark system=linear hydra.run.dir=outputs/bouc_wen_benchmark
	$(PY) experiments/benchmark_test_signals.py bouc_wen outputs/bouc_wen_benchmark
	$(PY) diagnose.py data=silverbox system=linear hydra.run.dir=outputs/silverbox
	$(PY) experiments/benchmark_test_signals.py silverbox outputs/silverbox
	$(PY) experiments/silverbox_models.py --run outputs/silverbox

# the real-structure studies: every shipped Painter Street event as a Hydra multirun, the strong ones
# diagnosed; the three shake-table buildings (IMUs), each run identified and the others predicted ->
# experiments/results/real/ (installs the peer extra, mdof and quakeio, for SRIM / OKID-ERA)
PEER := $(VENV)/.peer
$(PEER): $(STAMP)
	$(PY) -m pip install -q -e ".[peer]"
	touch $(PEER)

real: $(PEER)
	$(PY) experiments/real.py $(ARGS)
	$(PY) experiments/deck_diagnosis.py
	$(PY) experiments/shake_table.py
