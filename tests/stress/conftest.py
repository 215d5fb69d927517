"""The stress suite: every test in this directory carries the ``stress`` marker.

Settings and strategies live in ``stress_support.py`` (``MORSUITE_STRESS_EXAMPLES``
sets the number of hypothesis examples per property test, default 12).
"""

from __future__ import annotations

import os

import pytest

_HERE = os.path.dirname(os.path.abspath(__file__))


def pytest_collection_modifyitems(config, items):
    for item in items:
        if str(item.fspath).startswith(_HERE):
            item.add_marker(pytest.mark.stress)
