"""Every refused input gets its documented error class and a message that names the problem.

One test per row of ``morsuite.stress.refused.CASES``; the README section
"Refused inputs" is generated from the same table
(``python -m morsuite.stress --refused-table``). Some rows repeat checks of
tests/test_models.py, test_io.py and test_studies.py on purpose: this table is
the complete list.
"""

from __future__ import annotations

import warnings

import pytest

import morsuite as ms
from morsuite.stress.refused import CASES, DATA_FILE

pytestmark = pytest.mark.stress


@pytest.mark.parametrize("case", CASES, ids=[c.key for c in CASES])
def test_refused_input(tmp_path, data_dir, case):
    if case.needs_data and not (data_dir / DATA_FILE).is_file():
        pytest.skip(f"{DATA_FILE} is not in {data_dir}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(case.error, match=case.match) as info:
            case.call(tmp_path, data_dir)
    assert isinstance(info.value, ms.MorsuiteError)
    # input errors stay catchable as ValueError (errors.py); solver/budget errors are not input errors
    if issubclass(case.error, ms.InputError):
        assert isinstance(info.value, ValueError)


def test_table_keys_are_unique():
    keys = [c.key for c in CASES]
    assert len(keys) == len(set(keys))


def test_table_leaves_out_rows_without_their_data_file(tmp_path, data_dir, monkeypatch, capsys):
    from morsuite.stress import refused

    pick = {c.key: c for c in CASES}
    monkeypatch.setattr(refused, "CASES", [pick["file-missing"], pick["mat-sign"], pick["r-zero"]])
    rows, skipped = refused.table_rows(tmp_path)  # no .mat file there
    assert skipped == ["mat-sign"] and [r[4] for r in rows] == ["file-missing", "r-zero"]
    assert rows[0][2] == "FileFormatError" and rows[0][3] == "model file '<dir>/nothing.npz' does not exist or is not a file"
    table = refused.markdown_table(tmp_path)
    assert "mat-sign" in capsys.readouterr().err and "`mat-sign`" not in table
    if (data_dir / DATA_FILE).is_file():
        rows, skipped = refused.table_rows(data_dir)
        assert not skipped and rows[1][3].startswith(f"tests/data/{DATA_FILE}: block A")
