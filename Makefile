# The two commands: `make run` and `make test`. Both create .venv and install on first use.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
EXTRAS := train,dev,bench,render,store,video,notebooks,viewer,ray
export NUMBA_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export SDL_VIDEODRIVER ?= dummy
export MPLBACKEND ?= Agg

.PHONY: run test test-fast bench fuzz lint install clean browser

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

# The browser tests (tests/test_web_*.py) drive the system's Chromium through Playwright; Debian's package is
# installed here when missing (Playwright's own browser download is never used). The live-window tests
# (tests/test_render_window.py) open a real pygame window on an Xvfb server (Debian's xvfb, installed likewise).
browser:
	@command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || { \
	  echo "installing Chromium (Debian package) for the browser tests"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq chromium >/dev/null; }
	@command -v Xvfb >/dev/null 2>&1 || { \
	  echo "installing Xvfb (Debian package) for the live-window tests"; \
	  if [ "$$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq xvfb >/dev/null; }

test: $(STAMP) browser
	$(PY) -m pytest -n 2 -q tests

test-fast: $(STAMP)
	$(PY) -m pytest -n 2 -q -m "not slow" tests

bench: $(STAMP) browser
	$(PY) benchmarks/run_all.py

# hypothesis fuzz of every scenario, long profile: AGENTSIM_FUZZ_EXAMPLES examples in all (tests/test_fuzz.py)
fuzz: $(STAMP)
	AGENTSIM_FUZZ_EXAMPLES=$${AGENTSIM_FUZZ_EXAMPLES:-10000} $(PY) -m pytest -q -p no:randomly tests/test_fuzz.py

lint: $(STAMP)
	$(VENV)/bin/ruff check agentsim_env policies train tests benchmarks
	$(VENV)/bin/ruff format --check agentsim_env policies train tests benchmarks examples $(wildcard docs/*.py)
	$(VENV)/bin/mypy agentsim_env policies train

clean:
	rm -rf $(VENV) outputs .pytest_cache .hypothesis

# Other RL stacks: one virtual environment per stack under .venv-eco/ (BenchMARL pins an older TorchRL than
# TorchRL's latest, AgileRL an older PettingZoo), built once from the versions verified in
# examples/constraints-<stack>.txt (torch stays the CPU build) and rebuilt when pyproject.toml or those pins
# change; then each example runs a few hundred frames. `make test-ecosystem-<stack>` builds and runs one stack.
ECO := .venv-eco
ECO_FRAMES ?= 400
ECO_TIMEOUT ?= 300
ECO_STACKS := rllib torchrl benchmarl cleanrl skrl agilerl

.PHONY: test-ecosystem $(addprefix test-ecosystem-,$(ECO_STACKS))

$(ECO)/%/.installed: pyproject.toml examples/constraints-%.txt
	test -x $(ECO)/$*/bin/python || $(PYTHON) -m venv $(ECO)/$*
	$(ECO)/$*/bin/python -m pip install -q --upgrade pip
	$(ECO)/$*/bin/python -m pip install -q -c examples/constraints-$*.txt "torch==2.13.0+cpu"
	$(ECO)/$*/bin/python -m pip install -q -c examples/constraints-$*.txt -e ".[$*]"
	touch $@

# $(call eco_run,stack,example and arguments): run under a time limit, print the wall time
eco_run = @echo "== $(1): $(2)"; s=$$(date +%s); timeout $(ECO_TIMEOUT) $(ECO)/$(1)/bin/python $(2) \
	&& echo "== $(1): passed in $$(( $$(date +%s) - s )) s"

test-ecosystem: test-ecosystem-rllib test-ecosystem-torchrl test-ecosystem-benchmarl test-ecosystem-cleanrl test-ecosystem-skrl test-ecosystem-agilerl

test-ecosystem-rllib: $(ECO)/rllib/.installed
	$(call eco_run,rllib,examples/rllib_ppo_shared.py --frames $(ECO_FRAMES) --iterations 2)

test-ecosystem-torchrl: $(ECO)/torchrl/.installed
	$(call eco_run,torchrl,examples/torchrl_mappo.py --frames $(ECO_FRAMES) --frames-per-batch 200)

test-ecosystem-benchmarl: $(ECO)/benchmarl/.installed
	$(call eco_run,benchmarl,examples/benchmarl_mappo.py --frames $(ECO_FRAMES) --out outputs/benchmarl)

test-ecosystem-cleanrl: $(ECO)/cleanrl/.installed
	$(call eco_run,cleanrl,examples/cleanrl_ppo.py --frames $(ECO_FRAMES) --num-steps 100 --num-minibatches 4 \
	  --runs-dir outputs/cleanrl)

test-ecosystem-skrl: $(ECO)/skrl/.installed
	$(call eco_run,skrl,examples/skrl_mappo.py --frames $(ECO_FRAMES) --rollouts 100 --out outputs/skrl)

test-ecosystem-agilerl: $(ECO)/agilerl/.installed
	$(call eco_run,agilerl,examples/agilerl_matd3.py --frames $(ECO_FRAMES) --envs 2 --population 2 \
	  --out outputs/agilerl)
