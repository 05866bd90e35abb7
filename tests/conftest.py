"""Session hooks: the simulator's kernel is compiled once, before any test, where numba's cache
does not hold it, and the agents' decision ahead of time where it is not built; the ``browser`` tests run where Chromium and Playwright are, and are
deselected elsewhere, with one line in the summary saying why; under pytest-xdist
(``--dist loadgroup``, as ``make test`` and ``make test-all`` run it), the tests that must share
a worker are grouped onto one, and the longest work is handed out first (``durations.json``)."""

import json
import re
from pathlib import Path

import pytest

from tests.browser import unavailable

DESELECTED = pytest.StashKey[str]()

BROWSER_GROUP = "browser"
"""The browser tests' worker: one SwiftShader at a time, since two viewers drawing at once on a
2-core machine starve each other."""


DURATIONS = Path(__file__).with_name("durations.json")
"""Each test's seconds (its setup, call and teardown) in a whole run of the suite in parallel on
a 2-core machine, written by ``make test-durations``: the parallel pass hands out its work
longest first, so that no long test or group starts last and runs alone at the end."""

UNMEASURED_S = 1.0
"""The seconds assumed of a test the file does not name yet (a test is typically 0.1 to 5)."""

GROUP_SUFFIX = re.compile(r"@[^@\[\]]+$")
"""What pytest-xdist's loadgroup appends to a grouped test's id (``@`` and the group)."""


def pytest_sessionstart(session):
    """Compile the simulator's kernel here, once, if numba's cache does not hold it (the first
    checkout of these kernel sources on this machine, ``protocol.jit``), before the workers
    start: else the first tests to play it (the experiment's command, in a process of its
    own) each compiled it at once, several times half a minute on a loaded machine, and ran past
    their time-outs. The same for the kernels compiled ahead of time (``learning.ahead``,
    ``world.rules_ahead``), which every process that starts a swarm would otherwise build, or
    wait for, at once. In the controller only: a worker finds them cached."""
    if hasattr(session.config, "workerinput"):
        return
    from nnql_swarm.learning import ahead
    from nnql_swarm.world.rules_ahead import RULES
    from nnql_swarm.launch.cli import prepare_simulator
    from nnql_swarm.protocol.config import SwarmConfig
    from nnql_swarm.sim.runs import swarm_world

    config = SwarmConfig(n_agents=2, width=5, height=5, episodes=1, max_steps=10)
    prepare_simulator(swarm_world(config), config)  # says so when it compiles
    for module in (ahead.KERNELS, RULES):
        module.ensure()  # says so when it compiles


def pytest_addoption(parser):
    parser.addoption("--store-durations", action="store_true",
                     help=f"write each test's seconds into {DURATIONS.name} (make "
                          f"test-durations), which orders the parallel pass's work")


def shared_fixture_modules(session, items) -> set[str]:
    """The modules that define a fixture of module (or wider) scope: their tests run on one
    worker, so that each such fixture (a run, a router, a LAN of namespaces) is built once. A
    test may reach such a fixture by name at run time (``request.getfixturevalue``), so the
    whole module goes together, not just the tests that name it."""
    manager = session._fixturemanager
    shared = set()
    for module in {item.getparent(pytest.Module) for item in items}:
        if module is None:
            continue
        for name in vars(module.obj):
            if any(d.scope != "function" and d.baseid == module.nodeid
                   for d in manager.getfixturedefs(name, module) or ()):
                shared.add(module.nodeid)
                break
    return shared


@pytest.hookimpl(tryfirst=True)  # before xdist reads the groups into the tests' ids
def pytest_collection_modifyitems(session, config, items):
    browser = [item for item in items if item.get_closest_marker("browser")]
    reason = unavailable() if browser else None
    if reason is not None:
        config.hook.pytest_deselected(items=browser)
        items[:] = [item for item in items if not item.get_closest_marker("browser")]
        config.stash[DESELECTED] = (f"deselected {len(browser)} browser tests: {reason}; "
                                    f"`make browser-test` installs what they need (Chromium "
                                    f"as root, with apt-get)")
    shared = shared_fixture_modules(session, items)
    for item in items:
        module = item.getparent(pytest.Module)
        if item.get_closest_marker("browser"):
            item.add_marker(pytest.mark.xdist_group(BROWSER_GROUP))
        elif module is not None and module.nodeid in shared:
            item.add_marker(pytest.mark.xdist_group(module.nodeid))
    if hasattr(config, "workerinput"):  # an xdist worker: its order is the one handed out
        longest_first(items, json.loads(DURATIONS.read_text()) if DURATIONS.exists() else {})


def longest_first(items: list, durations: dict[str, float]) -> None:
    """Reorder ``items`` so that the units xdist hands out (a group, or a test alone) come
    longest first, each unit's tests in their order; with ``--no-loadscope-reorder`` (the
    Makefile's), xdist hands them out in this order, to each worker as it becomes free."""
    units: dict[str, list] = {}
    for item in items:
        group = item.get_closest_marker("xdist_group")
        units.setdefault(group.args[0] if group else item.nodeid, []).append(item)
    seconds = {unit: sum(durations.get(item.nodeid, UNMEASURED_S) for item in members)
               for unit, members in units.items()}
    items[:] = [item for unit in sorted(units, key=lambda u: -seconds[u]) for item in units[unit]]


_SPENT: dict[str, float] = {}
"""This run's seconds of each test so far, by its id without xdist's group."""


def pytest_runtest_logreport(report):
    nodeid = GROUP_SUFFIX.sub("", report.nodeid)
    _SPENT[nodeid] = _SPENT.get(nodeid, 0.0) + report.duration


def pytest_sessionfinish(session):
    """With --store-durations, in the process that sees every test (xdist's controller, or the
    only one): this run's seconds merged into the file's, one per line."""
    config = session.config
    if not config.getoption("store_durations") or hasattr(config, "workerinput"):
        return
    durations = json.loads(DURATIONS.read_text()) if DURATIONS.exists() else {}
    durations.update({nodeid: round(seconds, 2) for nodeid, seconds in _SPENT.items()})
    DURATIONS.write_text(json.dumps(dict(sorted(durations.items())), indent=0) + "\n")


def pytest_collection_finish(session):
    """In an xdist worker of ``--dist loadgroup``: each grouped test's id carries its group, or
    the groups were lost (pytest-xdist 3.8 under pytest 9.2, pytest-xdist#1386) and the run
    would build the shared fixtures once per worker and start browsers side by side."""
    if not getattr(session.config.option, "loadgroup", False):
        return
    lost = [item.nodeid for item in session.items
            if item.get_closest_marker("xdist_group") and "@" not in item.nodeid]
    if lost:
        raise pytest.UsageError(f"pytest-xdist lost the xdist_group of {len(lost)} tests "
                                f"({lost[0]}, ...): this pytest and pytest-xdist do not work "
                                f"together; pyproject.toml's test extra names ones that do")


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if DESELECTED in config.stash:
        terminalreporter.write_line(config.stash[DESELECTED], yellow=True)
