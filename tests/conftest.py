"""Session hooks: the ``browser`` tests run where Chromium and Playwright are, and are
deselected elsewhere, with one line in the summary saying why."""

import pytest

from tests.browser import unavailable

DESELECTED = pytest.StashKey[str]()


def pytest_collection_modifyitems(config, items):
    browser = [item for item in items if item.get_closest_marker("browser")]
    reason = unavailable() if browser else None
    if reason is None:
        return
    config.hook.pytest_deselected(items=browser)
    items[:] = [item for item in items if not item.get_closest_marker("browser")]
    config.stash[DESELECTED] = (f"deselected {len(browser)} browser tests: {reason}; "
                                f"`make browser-test` installs what they need (Chromium as "
                                f"root, with apt-get)")


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if DESELECTED in config.stash:
        terminalreporter.write_line(config.stash[DESELECTED], yellow=True)
