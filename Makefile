# The two commands: `make run` and `make test`. Both create .venv and install on first use.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
EXTRAS := train,dev,bench,render,store,video
export NUMBA_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export SDL_VIDEODRIVER ?= dummy
export MPLBACKEND ?= Agg

.PHONY: run test test-fast bench fuzz lint install clean

$(STAMP): pyproject.toml constraints.txt
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	# torch first, pinned to the CPU build, so nothing pulls CUDA packages
	$(PY) -m pip install -q -c constraints.txt "torch==2.13.0+cpu"
	$(PY) -m pip install -q -c constraints.txt -e ".[$(EXTRAS)]"
	$(VENV)/bin/agentsim warmup --quiet
	touch $(STAMP)

install: $(STAMP)

run: $(STAMP)
	$(VENV)/bin/agentsim evaluate --zones default --strategies all --seeds 3 --out outputs/evaluation

test: $(STAMP)
	$(PY) -m pytest -n 2 -q tests

test-fast: $(STAMP)
	$(PY) -m pytest -n 2 -q -m "not slow" tests

bench: $(STAMP)
	$(PY) benchmarks/run_all.py

# hypothesis fuzz of every scenario, long profile: AGENTSIM_FUZZ_EXAMPLES examples in all (tests/test_fuzz.py)
fuzz: $(STAMP)
	AGENTSIM_FUZZ_EXAMPLES=$${AGENTSIM_FUZZ_EXAMPLES:-10000} $(PY) -m pytest -q -p no:randomly tests/test_fuzz.py

lint: $(STAMP)
	$(VENV)/bin/ruff check agentsim_env policies train tests benchmarks
	$(VENV)/bin/mypy agentsim_env policies train

clean:
	rm -rf $(VENV) outputs .pytest_cache .hypothesis
