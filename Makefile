# Two commands for a fresh machine: `make run` (the swarm) and `make test` (the type checker over
# the package, then the test suite's fast tier: every room, in minutes). `make test-all` runs the
# whole suite (the fast tier and the tests marked `full`), as CI does (.ci/run), and lists the
# 20 slowest tests of each pass, to keep the suite's time in view. Each runs its tests in two
# passes: all but those marked `serial` on TEST_WORKERS pytest-xdist workers (most tests wait on
# real processes, so more workers than cores pay), then the `serial` ones alone.
# Both create a local virtualenv in .venv and install the project into it first.
# `make browser-test` installs Debian's chromium (as root, with apt-get) and Playwright, and runs
# the tests of the web viewer in headless Chromium (`make test` runs them too when both are there).
# `make netfault-tools` installs Debian's iproute2 (ip, tc) and iptables where missing (as root),
# which the tests of faults on the real network between namespace hosts use (tests/test_netfaults.py).

PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
BROWSER_STAMP := $(VENV)/.browser
CHROMIUM := /usr/bin/chromium

AGENTS ?= 8
ARGS ?=
TEST_WORKERS ?= 3

# $(call tiers,MARKERS[,OPTIONS]): the tests MARKERS selects (all if empty), in parallel then
# serially; both passes run, and either failing fails. Exit code 5 is pytest's "no tests
# selected". The parallel pass hands out its work longest first (tests/durations.json, by
# tests/conftest.py), which --no-loadscope-reorder keeps.
tiers = $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadgroup --no-loadscope-reorder $(2) \
	  -m "$(if $(1),($(1)) and )not serial"; parallel=$$?; \
	$(PY) -m pytest -q $(2) -m "$(if $(1),($(1)) and )serial"; serial=$$?; \
	[ $$serial = 5 ] && serial=0; exit $$(( parallel || serial ))

.PHONY: run test test-all test-durations chromium netfault-tools playwright browser-test experiment bench clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	@# pip's log (and setuptools' note that an editable install maps folders) goes to a file,
	@# shown if the install fails.
	$(PY) -m pip install --quiet -e '.[test,plot]' >$(VENV)/install.log 2>&1 || \
	  { cat $(VENV)/install.log; exit 1; }
	touch $(STAMP)

run: $(STAMP)
	$(PY) launch/swarm.py --agents $(AGENTS) $(ARGS)

test: $(STAMP)
	$(PY) -m mypy
	$(call tiers,not full)

test-all: $(STAMP)
	$(PY) -m mypy
	$(call tiers,,--durations=20)

# The whole suite, as test-all, writing each test's seconds into tests/durations.json (commit it
# after adding or changing long tests).
test-durations: $(STAMP)
	$(call tiers,,--store-durations)

# Debian's chromium, installed only if missing; fails (saying why) where that needs root or apt-get.
chromium:
	@test -x $(CHROMIUM) || { \
	  if [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then \
	    echo "chromium: $(CHROMIUM) is missing, and installing it needs root and apt-get" >&2; \
	    exit 1; \
	  fi; \
	  echo "chromium: installing Debian's chromium with apt-get"; \
	  log=$$(mktemp); \
	  if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
	         apt-get install -y -qq chromium; } >$$log 2>&1; then \
	    tail -n 20 $$log >&2; rm -f $$log; exit 1; \
	  fi; \
	  rm -f $$log; \
	  test -x $(CHROMIUM) || { echo "chromium: installed, but $(CHROMIUM) is still missing" >&2; \
	                           exit 1; }; \
	}

# ip and tc (iproute2) and iptables, installed only if missing; fails (saying why) where that needs
# root or apt-get. Whether the kernel has netem is another matter: tests/netns.py probes it.
netfault-tools:
	@missing=""; \
	command -v ip >/dev/null && command -v tc >/dev/null || missing=" iproute2"; \
	command -v iptables >/dev/null || missing="$$missing iptables"; \
	test -z "$$missing" || { \
	  if [ "$$(id -u)" != 0 ] || ! command -v apt-get >/dev/null; then \
	    echo "netfault-tools:$$missing missing, and installing needs root and apt-get" >&2; \
	    exit 1; \
	  fi; \
	  echo "netfault-tools: installing Debian's$$missing with apt-get"; \
	  log=$$(mktemp); \
	  if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
	         apt-get install -y -qq $$missing; } >$$log 2>&1; then \
	    tail -n 20 $$log >&2; rm -f $$log; exit 1; \
	  fi; \
	  rm -f $$log; \
	}

playwright: $(BROWSER_STAMP)

$(BROWSER_STAMP): $(STAMP)
	$(PY) -m pip install --quiet -e '.[test,plot,browser]' >$(VENV)/install.log 2>&1 || \
	  { cat $(VENV)/install.log; exit 1; }
	touch $(BROWSER_STAMP)

browser-test: chromium $(BROWSER_STAMP)
	$(PY) -m pytest -q -m browser

experiment: $(STAMP)
	$(PY) launch/experiment.py $(ARGS)

bench: $(STAMP)
	$(PY) -m bench.table1
	$(PY) -m bench.sweep
	$(PY) -m bench.swarm_ticks
	$(PY) -m bench.recording_cost
	$(PY) -m bench.codec
	$(PY) -m bench.world_tick
	$(PY) -m bench.node_cpu

clean:
	rm -rf $(VENV) .pytest_cache .hypothesis
