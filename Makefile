# make demo: set up .venv and serve CartPole to a controller client.
# make test: set up .venv and run the test suite.
# make typecheck: mypy over the runtime and the client (the typecheck extra; .ci/run runs it).
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-lowest test-ray test-browser test-minari test-onnx test-dm-env-rpc\
	test-godot-rl test-openenv test-trainers test-package screenshot\
	screenshot-time-travel plinko-picture sb3 rllib cleanrl bench-http bench-train docs lint typecheck\
	vectors clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/rlenv demo

# The suite runs in up to 4 worker processes (pytest-xdist): every test binds port 0 and keeps
# its files in its own tmp_path, so they never meet; PYTEST_WORKERS=0 runs it in one process.
PYTEST_WORKERS ?= auto
PARALLEL := -n $(PYTEST_WORKERS) --maxprocesses 4

test: $(STAMP)
	$(BIN)/ruff check rlenv client tools examples tests benchmarks docs
	$(BIN)/ruff format --check rlenv client tools examples tests benchmarks docs
	$(BIN)/python -m pytest $(PARALLEL)

# Optional: servers on Ray (the ray extra) and their tests: one node, then a fake cluster.
test-ray: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,ray]"
	$(BIN)/python -m pytest -m ray

# Optional: recorded episodes as Minari datasets (the minari extra: rlenv dataset create,
# DataCollector, minari show), over real servers.
test-minari: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,minari]"
	$(BIN)/python -m pytest -m minari

# Optional: the dm_env_rpc server (the dm-env-rpc extra: grpcio, protobuf, dm-env-rpc): the
# wheel's own compliance tests on rlenv/CartPole-v1 and rlenv/Reacher-v0, and episodes through
# its DmEnvAdaptor (one and several agents) against gymnasium's, over real servers (about a minute).
test-dm-env-rpc: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,dm-env-rpc]"
	$(BIN)/python -m pytest -m dm_env_rpc tests/test_dm_env_rpc.py

# Optional: the inspector's page in headless Chromium (skipped, saying why, without one; .ci/run
# installs Debian's chromium first), and what watching costs a trainer.
test-browser: $(STAMP)
	$(BIN)/python -m pytest -m browser

# Optional: policies as ONNX files (the onnx extra): export (SB3 PPO, A2C, DQN, SAC; CPU torch
# first, as for sb3) and rlenv serve --policy over real servers (about 30 s).
test-onnx: $(STAMP)
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[test,sb3,onnx]"
	OMP_NUM_THREADS=1 $(BIN)/python -m pytest -m onnx tests/test_onnx_policies.py

# rlenv as users install it (the release extra: build, twine): the sdist and the wheel built and
# checked (twine check, only rlenv, rlenv_client and rlenv_tools at the top), the wheel installed with its http
# extra into a new venv outside the checkout, where rlenv demo, rlenv check, a gym.make episode
# and rlenv http run (.ci/test-package; about a minute, most of it pip).
test-package: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,release]"
	PYTHON=$(PYTHON) .ci/test-package $(BIN)/python

# The README's picture of the inspector: its page beside a training loop, saved by the browser
# test; and docs/time-travel.md's pictures (docs/images/time-travel-*.png): see screenshot-time-travel.
screenshot: $(STAMP) screenshot-time-travel
	RLENV_SCREENSHOT=docs/images/inspector.png $(BIN)/python -m pytest -m browser -q \
		tests/test_inspector_browser.py -k training

# docs/time-travel.md's pictures: the page scrubbing and branching examples/time_travel.py's failure.
screenshot-time-travel: $(STAMP)
	RLENV_SCREENSHOT_DIR=docs/images $(BIN)/python -m pytest -m browser -q \
		tests/test_inspector_browser.py -k time_travel

# The picture in docs/procedural.md: two Plinko levels drawn by rlenv's own renderer.
plinko-picture: $(STAMP)
	$(BIN)/python -m examples.plinko.picture docs/images/plinko-levels.png

# Optional: RLlib (CPU torch first), its tests, and PPO trained on CartPole to a mean return of 400.
rllib: $(STAMP)
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[test,rllib]"
	$(BIN)/python -m pytest -m ray tests/test_rllib.py
	$(BIN)/python -m examples.train_rllib

# Optional: Stable-Baselines3, its tests, a training run (about 90 s). torch 2.13.0 first: a CPU
# build where its wheel is at hand (this project's machines); elsewhere install a CPU torch
# first (see the README), or pip pulls a CUDA build.
sb3: $(STAMP)
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[test,sb3]"
	$(BIN)/python -m pytest tests/test_sb3.py tests/test_interruptions.py -k "sb3 or SB3"
	$(BIN)/python -m examples.train_sb3

# Optional: the documentation site, with the API reference made from the docstrings (the docs
# extra): its tests (a strict build, the reference covers what users touch), then site/index.html.
docs: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,docs]"
	$(BIN)/python -m pytest -m docs tests/test_docs.py
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --quiet

# Optional: CleanRL's ppo.py, unmodified, on gymnasium's CartPole-v1 and on rlenv/CartPole-v1: its
# SPS on each with 4 and 8 envs, rounds in turns (benchmarks/cleanrl_speed.py, a few minutes), then
# their learning curves side by side (benchmarks/cleanrl_curves.py; about 10 minutes a seed).
# ppo.py is not part of rlenv: pass CLEANRL_PPO=path/to/cleanrl/ppo.py, or where the network
# reaches GitHub the target downloads it at a pinned commit and checks its sha256. Its venv,
# .venv-cleanrl, gets the CPU torch first (so no CUDA build is pulled), then rlenv, tyro and
# tensorboard. CLEANRL_STEPS=N shortens the runs; CLEANRL_SEEDS="1 2" runs more seeds.
CLEANRL_VENV := .venv-cleanrl
CLEANRL_COMMIT := fe8d8a03c41a7ef5b523e2e354bd01c363e786bb
CLEANRL_SHA256 := d8dfbb7ac0b21e747b77d6e6673e566db4d6cdacc83bcebcd19cf87ad0e459ae
CLEANRL_PPO ?= $(CLEANRL_VENV)/ppo.py
CLEANRL_STEPS ?= 500000
CLEANRL_SEEDS ?= 1

$(CLEANRL_VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(CLEANRL_VENV)
	$(CLEANRL_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(CLEANRL_VENV)/bin/python -m pip install --quiet torch==2.13.0
	$(CLEANRL_VENV)/bin/python -m pip install --quiet -e . tyro tensorboard
	touch $@

$(CLEANRL_VENV)/ppo.py: | $(CLEANRL_VENV)/.installed
	curl -fsSL -o $@.part \
		https://raw.githubusercontent.com/vwxyzjn/cleanrl/$(CLEANRL_COMMIT)/cleanrl/ppo.py \
		|| { rm -f $@.part; echo "cannot download ppo.py here: fetch cleanrl/ppo.py from" \
		"vwxyzjn/cleanrl and run make cleanrl CLEANRL_PPO=path/to/ppo.py"; exit 1; }
	echo "$(CLEANRL_SHA256)  $@.part" | sha256sum --check --quiet
	mv $@.part $@

cleanrl: $(CLEANRL_VENV)/.installed $(CLEANRL_PPO)
	$(CLEANRL_VENV)/bin/python benchmarks/cleanrl_speed.py $(CLEANRL_PPO)
	$(CLEANRL_VENV)/bin/python benchmarks/cleanrl_curves.py $(CLEANRL_PPO) \
		--total-timesteps $(CLEANRL_STEPS) --seeds $(CLEANRL_SEEDS)

# Optional: Godot RL Agents (godot-rl 0.8.2) trains rlenv environments with its own, unmodified
# examples/stable_baselines3_example.py (tests/test_godot_rl.py: CartPole-v1 through a launcher
# as env_path with n_parallel=2, to a mean episode length of 400, then Pair; a few minutes).
# godot-rl pins gymnasium <= 1.0.0, so it gets a venv of its own, .venv-godot-rl (the CPU torch
# first); rlenv runs beside it from .venv as rlenv godot-rl. The example is not part of rlenv:
# pass GODOT_RL_EXAMPLE=path/to/stable_baselines3_example.py, or where the network reaches GitHub
# the target downloads it at godot-rl v0.8.2's commit and checks its sha256. It listens on
# 127.0.0.1:11008 and 11009, which must be free.
GODOT_RL_VENV := .venv-godot-rl
GODOT_RL_COMMIT := f4b53921f0f6602d930b7b174a3ba7b8aed361aa
GODOT_RL_SHA256 := e4b9c169e3ce9d67031958c6588d1ee8c3262427d52076f0559c6f6279f4449c
GODOT_RL_EXAMPLE ?= $(GODOT_RL_VENV)/stable_baselines3_example.py

$(GODOT_RL_VENV)/.installed:
	$(PYTHON) -m venv $(GODOT_RL_VENV)
	$(GODOT_RL_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(GODOT_RL_VENV)/bin/python -m pip install --quiet torch==2.13.0
	$(GODOT_RL_VENV)/bin/python -m pip install --quiet godot-rl==0.8.2
	touch $@

$(GODOT_RL_VENV)/stable_baselines3_example.py:
	mkdir -p $(GODOT_RL_VENV)
	if curl -fsSL -o $@.part https://raw.githubusercontent.com/edbeeching/godot_rl_agents/$(GODOT_RL_COMMIT)/examples/stable_baselines3_example.py; then \
		echo "$(GODOT_RL_SHA256)  $@.part" | sha256sum --check --quiet && mv $@.part $@; \
	else rm -f $@.part; echo "cannot download godot-rl's example here (no access to GitHub)"; fi

# Without the example (no GitHub, no GODOT_RL_EXAMPLE), the target says so and runs nothing,
# as test-browser does without Chromium.
test-godot-rl: $(STAMP) $(GODOT_RL_EXAMPLE)
	@if [ ! -f "$(GODOT_RL_EXAMPLE)" ]; then echo "make test-godot-rl: not run: godot-rl's" \
		"examples/stable_baselines3_example.py is not here; fetch it from" \
		"edbeeching/godot_rl_agents and run make test-godot-rl GODOT_RL_EXAMPLE=path/to/it"; \
	else $(MAKE) --no-print-directory $(GODOT_RL_VENV)/.installed && \
		GODOT_RL_PYTHON=$(abspath $(GODOT_RL_VENV))/bin/python \
		GODOT_RL_EXAMPLE=$(abspath $(GODOT_RL_EXAMPLE)) OMP_NUM_THREADS=1 \
		$(BIN)/python -m pytest -m godot_rl tests/test_godot_rl.py; fi

# Optional: OpenEnv's own client (openenv-core 0.3.0's GenericEnvClient) plays rlenv/CartPole-v1
# and rlenv/Pair-v0 through rlenv http's /openenv routes, bit for bit like gym.make
# (tests/test_openenv.py; under a minute, after pip). openenv-core brings FastAPI, Gradio, the OpenAI client and
# fastmcp, none of which rlenv needs, so it gets a venv of its own, .venv-openenv, beside rlenv's
# test extra.
OPENENV_VENV := .venv-openenv

$(OPENENV_VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(OPENENV_VENV)
	$(OPENENV_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(OPENENV_VENV)/bin/python -m pip install --quiet openenv-core==0.3.0 -e ".[test]"
	touch $@

test-openenv: $(OPENENV_VENV)/.installed
	$(OPENENV_VENV)/bin/python -m pytest -m openenv tests/test_openenv.py

# Optional: the trainer matrix (.ci/test-trainers): docs/other-trainers.md's recipes
# (examples/recipes: PufferLib, TorchRL, Sample Factory, gymnasium's benchmark_step) as smoke
# tests, each library in a venv of its own under TRAINERS_VENVS (the CPU torch first; never .venv),
# at the versions the page's table gives. A library pip cannot install here is reported "not
# run", with pip's reason; a recipe that fails fails the target. About a minute a recipe once the
# venvs are made (RECIPES="torchrl pufferlib" runs some).
TRAINERS_VENVS ?= .venv-trainers
RECIPES ?=

test-trainers:
	PYTHON=$(PYTHON) .ci/test-trainers $(TRAINERS_VENVS) $(RECIPES)

# Optional: what serving costs a real trainer (benchmarks/train_speed.py: SB3 PPO and SyncVectorEnv
# against the environment in process, under three conditions; about 15 minutes). torch first.
bench-train: $(STAMP)
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[test,sb3]"
	$(BIN)/python benchmarks/train_speed.py

# Optional: a step through the HTTP gateway (rlenv http, the http extra) against a TCP step.
bench-http: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[http]"
	$(BIN)/python benchmarks/http_step.py --implementations

# The suite against the lowest versions pyproject.toml allows (.ci/lowest.txt), in .venv-lowest.
LOWEST_VENV := .venv-lowest
$(LOWEST_VENV)/.installed: pyproject.toml .ci/lowest.txt
	$(PYTHON) -m venv $(LOWEST_VENV)
	$(LOWEST_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(LOWEST_VENV)/bin/python -m pip install --quiet -c .ci/lowest.txt -e ".[test]"
	touch $@

test-lowest: $(LOWEST_VENV)/.installed
	$(LOWEST_VENV)/bin/python -m pytest $(PARALLEL)

# The linter, then the formatter (ruff format, pinned in the test extra: its output is checked).
lint: $(STAMP)
	$(BIN)/ruff check rlenv client tools examples tests benchmarks docs
	$(BIN)/ruff format rlenv client tools examples tests benchmarks docs

# The type checker: mypy with pyproject.toml's [tool.mypy] (its files: rlenv and
# client/rlenv_client), 0 errors and no unused "type: ignore" (the typecheck extra installs it).
typecheck: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,typecheck]"
	$(BIN)/mypy

# Regenerate the protocol test vectors (docs/protocol/vectors/) by driving real servers.
vectors: $(STAMP)
	$(BIN)/python -m tests.protocol_vectors

clean:
	rm -rf $(VENV) $(CLEANRL_VENV) $(GODOT_RL_VENV) $(OPENENV_VENV) $(LOWEST_VENV) \
		$(TRAINERS_VENVS) build dist site *.egg-info
