"""Settings shared by every test."""

from collections.abc import Iterator

import pytest
import structlog
from hypothesis import settings

# Property tests judge outcomes, never speed: a machine that stalls for a moment (a loaded
# CI runner, a busy VM) must not fail one by hypothesis's per-example deadline.
settings.register_profile("fcmaster", deadline=None)
settings.load_profile("fcmaster")


@pytest.fixture(autouse=True)
def _structlog_as_found() -> Iterator[None]:
    """Logging set up by a test (the CLI's ``main`` configures it) ends with that test.

    Otherwise the next test's loggers are bound under its level: a CLI test's "warning" would
    silently drop the info lines another test captures.
    """
    yield
    structlog.reset_defaults()
