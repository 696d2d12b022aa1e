"""Fixtures several test files share."""

import pytest

from tofnet.backends.registry import _registered, register_backend


@pytest.fixture
def registered():
    """``registered(name, factory)``: a backend registered for one test, gone after it."""
    names = []

    def register(name, factory):
        register_backend(name, factory)
        names.append(name)
    yield register
    for name in names:
        _registered.pop(name, None)
