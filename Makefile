# make demo: set up .venv and serve CartPole to a controller client.
# make test: set up .venv and run the test suite.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-ray test-browser screenshot sb3 rllib bench-http lint vectors clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/rlenv demo

test: $(STAMP)
	$(BIN)/ruff check rlenv client examples tests benchmarks
	$(BIN)/python -m pytest

# Optional: servers on Ray (the ray extra) and their tests: one node, then a fake cluster.
test-ray: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,ray]"
	$(BIN)/python -m pytest -m ray

# Optional: the inspector's page in headless Chromium (skipped, saying why, without one; .ci/run
# installs Debian's chromium first), and what watching costs a trainer.
test-browser: $(STAMP)
	$(BIN)/python -m pytest -m browser

# The README's picture of the inspector: its page beside a training loop, saved by the browser test.
screenshot: $(STAMP)
	RLENV_SCREENSHOT=docs/images/inspector.png $(BIN)/python -m pytest -m browser -q \
		tests/test_inspector_browser.py -k training

# Optional: RLlib (CPU torch first), its tests, and PPO trained on CartPole to a mean return of 400.
rllib: $(STAMP)
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[test,rllib]"
	$(BIN)/python -m pytest -m ray tests/test_rllib.py
	$(BIN)/python -m examples.train_rllib

# Optional: Stable-Baselines3 (CPU torch first, so no CUDA build is pulled), its tests, a training run.
sb3: $(STAMP)
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e ".[test,sb3]"
	$(BIN)/python -m pytest tests/test_sb3.py
	$(BIN)/python -m examples.train_sb3

# Optional: a step through the HTTP gateway (rlenv http, the http extra) against a TCP step.
bench-http: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[http]"
	$(BIN)/python benchmarks/http_step.py --implementations

lint: $(STAMP)
	$(BIN)/ruff check rlenv client examples tests benchmarks

# Regenerate the protocol test vectors (docs/protocol/vectors/) by driving real servers.
vectors: $(STAMP)
	$(BIN)/python -m tests.protocol_vectors

clean:
	rm -rf $(VENV) build *.egg-info
