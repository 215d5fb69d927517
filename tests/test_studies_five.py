"""The five methods of issue 19 in one study: first-order and second-order ROMs on the axis of
first-order states (``r_by_method``, ``axis = "states"``), with band, H2 and Hinf errors.

Small models: dsms(g = 40), tcom(nc = 20); second-order ROMs at r = 2, 4 and first-order ROMs
at 4, 8 states. The H2 and Hinf errors in the summary are checked against the dense references
of ``test_studies_norms_time`` (the error system on an explicit null(G) basis: scipy's Lyapunov
solver, slycot's ab13dd); the rest checks what the scenes show and what the spec refuses.
"""

from __future__ import annotations

import pandas as pd
import pytest

import morsuite as ms
from morsuite.errors import SpecError
from morsuite.report.tables import read_markdown
from morsuite.studies import load_spec, run
from test_studies_norms_time import dense

FIVE = ["irka", "irka_fo", "so_h2", "bt", "bt_fo"]
FO = ("irka_fo", "bt_fo")

SPEC = """
name = "five"

[models]
dsms = "dsms:g=40"
tcom = "tcom:nc=20"

[grids]
g = { band = [1e-2, 1.0], n = 30 }

[methods.irka]
label = "IRKA"
options = { tol = 1e-6 }

[methods.irka_fo]
reducer = "irka-fo"
label = "irka-fo"

[methods.so_h2]
reducer = "so-h2"
label = "so-h2"

[methods.bt]
label = "BT (vv)"
options = { form = "vv" }

[methods.bt_fo]
reducer = "bt"
label = "BT, first-order"

[[scenes]]
name = "tcom_band_vs_states"
kind = "error_vs_r"
model = "tcom"
grid = "g"
r = [2, 4]
r_by_method = { irka_fo = [4, 8], bt_fo = [4, 8] }
measure = "max_abs"
axis = "states"

[[scenes]]
name = "tcom_h2_vs_states"
kind = "error_vs_r"
model = "tcom"
r = [2, 4]
r_by_method = { irka_fo = [4, 8], bt_fo = [4, 8] }
measure = "h2"
axis = "states"

[[scenes]]
name = "dsms_hinf_vs_states"
kind = "error_vs_r"
model = "dsms"
r = 4
r_by_method = { irka_fo = 8, bt_fo = 8 }
measure = "hinf"
axis = "states"

[[scenes]]
name = "tcom_time_vs_states"
kind = "time_vs_r"
model = "tcom"
r = [2, 4]
r_by_method = { irka_fo = [4, 8], bt_fo = [4, 8] }
axis = "states"

[[scenes]]
name = "tcom_pareto_h2"
kind = "pareto"
model = "tcom"
r = [2, 4]
r_by_method = { irka_fo = [4, 8], bt_fo = [4, 8] }
measure = "h2"
axis = "states"

[[scenes]]
name = "dsms_compare"
kind = "compare"
model = "dsms"
grid = "g"
r = 4
r_by_method = { irka_fo = 8, bt_fo = 8 }

[[scenes]]
name = "dsms_table"
kind = "table"
model = "dsms"
grid = "g"
r = 4
r_by_method = { irka_fo = 8, bt_fo = 8 }
norms = ["h2", "hinf"]
"""

OPTS = {"irka": (("tol", 1e-6),), "bt": (("form", "vv"),), "irka_fo": (), "so_h2": (), "bt_fo": ()}
REDUCER = {"irka": "irka", "irka_fo": "irka-fo", "so_h2": "so-h2", "bt": "bt", "bt_fo": "bt"}


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    from morsuite.studies import tasks

    for name in ("irka-fo", "so-h2"):
        if name not in ms.reducers.available():
            pytest.skip(f"reducer {name!r} not registered")
    tasks._model.cache_clear()
    tmp = tmp_path_factory.mktemp("five")
    (tmp / "five.toml").write_text(SPEC)
    return run(tmp / "five.toml", out=tmp / "results", quiet=True)


def _row(res, model, method, r):
    s = res.summary
    rows = s[(s.model == model) & (s.method == method) & (s.r_requested == r)]
    assert len(rows) == 1, (model, method, r)
    return rows.iloc[0]


def test_states_axis_puts_first_order_at_2r_beside_second_order_at_r(study):
    res = study
    for scene in ("tcom_band_vs_states", "tcom_h2_vs_states", "tcom_time_vs_states"):
        for m in FIVE:
            curve = pd.read_csv(res.outdir / f"{scene}__{m}.csv")
            assert curve.columns[0] == "states" and "r" in curve and "r_requested" in curve
            per = 1 if m in FO else 2   # states per order: a second-order ROM of order r has 2r
            assert list(curve.r_requested) == ([4, 8] if m in FO else [2, 4])
            assert list(curve.states) == [per * r for r in curve.r]
            assert list(curve.states) == [4, 8]   # where the two kinds meet
        assert (res.outdir / f"{scene}.png").stat().st_size > 0
    pareto = pd.read_csv(res.outdir / "tcom_pareto_h2__so_h2.csv")
    assert {"h2_error", "value", "states"} <= set(pareto.columns)
    tex = (res.outdir / "tcom_pareto_h2.tex").read_text()
    assert "meta=states" in tex    # the points are labelled by their states


def test_norms_of_all_five_against_dense_references(study):
    res = study
    for m in FIVE:
        r = 8 if m in FO else 4
        ref = dense("dsms:g=40", REDUCER[m], r, OPTS[m])
        row = _row(res, "dsms(g=40)", m, r)
        assert row.status == "ok" and row.states == 8
        # errors of 1e-5..1e-2 of ||T||: the Lyapunov reference keeps 8 digits or more there
        assert row.h2_error == pytest.approx(ref["h2"], rel=1e-6), m
        assert row.hinf_error == pytest.approx(ref["hinf"], rel=1e-6), m
        assert row.h2_rel_error == pytest.approx(ref["h2"] / ref["norm_h2"], rel=1e-6)
        curve = pd.read_csv(res.outdir / f"dsms_hinf_vs_states__{m}.csv")
        assert curve.value.iloc[0] == pytest.approx(ref["hinf"], rel=1e-6)
    for m in FIVE:   # the TCOM's H2 errors are in the summary too (no Hinf: no scene asked)
        for r in ([4, 8] if m in FO else [2, 4]):
            row = _row(res, "tcom(nc=20)", m, r)
            assert row.h2_error > 0 and pd.isna(row.hinf_error)


def test_table_verdict_compares_at_equal_states(study):
    res = study
    md = (res.outdir / "dsms_table.md").read_text()
    table = read_markdown(res.outdir / "dsms_table.md")
    assert sorted(table.method) == sorted(FIVE) and {"h2_error", "hinf_error"} <= set(table.columns)
    rows = {m: _row(res, "dsms(g=40)", m, 8 if m in FO else 4) for m in FIVE}
    labels = {"irka": "IRKA", "irka_fo": "irka-fo", "so_h2": "so-h2", "bt": "BT (vv)", "bt_fo": "BT, first-order"}
    for col in ("h2_error", "hinf_error", "max_abs_error"):
        best = min(FIVE, key=lambda m: rows[m][col])
        assert f"8 states, {col}: {labels[best]} (" in md
    assert "r = 4, h2_error" not in md   # not grouped by r: irka-fo at r = 8 would have no rival
    assert "Compared at equal first-order states" in md and "irka_fo r = 8" in md and "so_h2 r = 4" in md


def test_compare_scene_one_order_per_method(study):
    res = study
    for m in FIVE:
        assert (res.outdir / f"dsms_compare__{m}.csv").is_file()
    assert res.manifest["scenes"][5]["r_by_method"] == {"irka_fo": [8], "bt_fo": [8]}


@pytest.mark.parametrize("value, match", [
    ("{ nope = [4] }", "unknown key 'nope'"),
    ("{ irka_fo = [4, 8] }", "one reduced order per method"),
    ("{ irka_fo = 0 }", "positive integer"),
])
def test_r_by_method_bad_input_names_the_key(tmp_path, value, match):
    text = SPEC.split("[[scenes]]")[0] + f"""
[[scenes]]
name = "cmp"
kind = "compare"
model = "dsms"
grid = "g"
r = 4
r_by_method = {value}
"""
    (tmp_path / "bad.toml").write_text(text)
    with pytest.raises(SpecError, match=match) as exc:
        load_spec(tmp_path / "bad.toml")
    assert "r_by_method" in str(exc.value)


def test_r_by_method_above_twice_the_order_is_refused(tmp_path):
    text = SPEC.split("[[scenes]]")[0] + """
[[scenes]]
name = "big"
kind = "error_vs_r"
model = "tcom"
grid = "g"
r = 2
r_by_method = { bt_fo = 100000 }
"""
    (tmp_path / "big.toml").write_text(text)
    with pytest.raises(SpecError, match=r"r_by_method\.bt_fo: r = 100000 exceeds 2 \(n1 - n2\)"):
        load_spec(tmp_path / "big.toml")
