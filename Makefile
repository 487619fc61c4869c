# The README's two commands. Both create .venv if it is missing and install what they need.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
# torch is pinned and installed before stable-baselines3, which would otherwise resolve the
# newest release with its CUDA packages.
TORCH := torch==2.13.0

.PHONY: evaluate test bench lint clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.core: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.dev: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet $(TORCH)
	$(BIN)/python -m pip install --quiet -e ".[rl,cluster,dev]"
	touch $(VENV)/.core $@

evaluate: $(VENV)/.core
	$(BIN)/python scripts/evaluate.py

# the suite spread over every core: its tests are independent and write only to tmp_path
test: $(VENV)/.dev
	$(BIN)/python -m pytest -n auto

bench: $(VENV)/.dev
	$(BIN)/python scripts/bench.py

lint: $(VENV)/.dev
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) results .pytest_cache
