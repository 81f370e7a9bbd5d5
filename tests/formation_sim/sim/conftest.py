"""Fixtures of the engine's tests."""

from __future__ import annotations

import pytest

from formation_agent.core import compiled


@pytest.fixture
def on_path():
    """`on_path(True)`: the compiled path, `on_path(False)`: pure Python; the path before the test
    comes back after it."""
    previous = compiled.active()
    yield compiled.use_compiled
    compiled.use_compiled(previous)
