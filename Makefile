# Two commands for a fresh machine: `make run` (the swarm) and `make test` (the test suite).
# Both create a local virtualenv in .venv and install the project into it first.

PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

AGENTS ?= 8
ARGS ?=

.PHONY: run test experiment bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,plot]'
	touch $(STAMP)

run: $(STAMP)
	$(PY) launch/swarm.py --agents $(AGENTS) $(ARGS)

test: $(STAMP)
	$(PY) -m pytest -q

experiment: $(STAMP)
	$(PY) launch/experiment.py $(ARGS)

bench: $(STAMP)
	$(PY) bench/table1.py
	$(PY) bench/swarm_ticks.py
	$(PY) bench/recording_cost.py
	$(PY) bench/swarm_collisions.py
	$(PY) bench/codec.py
	$(PY) bench/world_tick.py
	$(PY) bench/node_cpu.py

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
