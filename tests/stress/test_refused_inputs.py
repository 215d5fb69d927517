"""Every refused input gets its documented error class and a message that names the problem.

One test per row of ``refused_cases.CASES``; the README section "Refused
inputs" is generated from the same table (``python tests/stress/refused_table.py``).
Some rows repeat checks of tests/test_models.py, test_io.py and
test_studies.py on purpose: this table is the complete list.
"""

from __future__ import annotations

import warnings

import pytest

import morsuite as ms
from refused_cases import CASES

pytestmark = pytest.mark.stress


@pytest.mark.parametrize("key, area, what, call, exc, match", CASES, ids=[c[0] for c in CASES])
def test_refused_input(tmp_path, key, area, what, call, exc, match):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(exc, match=match) as info:
            call(tmp_path)
    assert isinstance(info.value, ms.MorsuiteError)
    # input errors stay catchable as ValueError (errors.py); solver/budget errors are not input errors
    if issubclass(exc, ms.InputError):
        assert isinstance(info.value, ValueError)


def test_table_keys_are_unique():
    keys = [c[0] for c in CASES]
    assert len(keys) == len(set(keys))
