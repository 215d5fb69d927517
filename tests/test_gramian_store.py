"""The Gramian factors shared across processes (morsuite.studies.gramian_store).

References: the factors of a fresh LR-ADI run in this process (the store must give them back
to rounding, with the record of the run that made them), the exact H2 norm from them, and the
rule that a run's workers pay a model's factors once.
"""

from __future__ import annotations

import numpy as np
import pytest

import morsuite as ms
from morsuite.analysis import h2_norm
from morsuite.linalg import gramians
from morsuite.studies.cache import Cache
from morsuite.studies.gramian_store import KIND, GramianStore


@pytest.fixture
def store(tmp_path):
    s = GramianStore(Cache(tmp_path / "cache"))
    previous = gramians.use_store(s)
    yield s
    gramians.use_store(previous)


def _close(a, b):
    scale = max(np.abs(a).max(initial=0.0), np.finfo(float).tiny)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-13 * scale)  # stored arrays, the same projection: measured equal


def test_round_trip_gives_the_factors_back():
    """factors_to_arrays -> factors_from_arrays on a new model object with the same matrices: the
    same factors (the constrained observability factor's pending projection made again), residual
    history, shifts and record; computed=False."""
    gf = gramians.gramian_factors(ms.models.dsms(200), use_cache=False)
    assert gf.observability.projector is not None  # dsms has a constraint: its projection is pending
    arrays, meta = gramians.factors_to_arrays(gf)
    back = gramians.factors_from_arrays(ms.models.dsms(200), arrays, meta)
    assert not back.computed and back.lu_count == gf.lu_count and back.time_s == gf.time_s
    assert back.options == gf.options
    for side in ("controllability", "observability"):
        a, b = getattr(gf, side), getattr(back, side)
        _close(b.position, a.position)
        _close(b.velocity, a.velocity)
        np.testing.assert_array_equal(b.residuals, a.residuals)
        np.testing.assert_array_equal(b.shifts, a.shifts)
        assert b.summary() == a.summary() or np.isnan(a.solve_rho)


def test_store_serves_a_second_model_object_and_keys_by_matrices(store):
    """A second model object with equal matrices reads the factors (no LR-ADI: computed False) and
    gets the same exact H2 norm; a model with other matrices, another salt or explicit shifts does not."""
    first = gramians.gramian_factors(ms.models.dsms(200))
    assert first.computed
    fom = ms.models.dsms(200)
    second = gramians.gramian_factors(fom)
    assert not second.computed and second.lu_count == first.lu_count
    assert gramians.cached_gramian_factors(fom) is not None  # kept in the model's cache too
    ref = h2_norm(ms.models.dsms(200))
    assert abs(h2_norm(fom) - ref) <= 1e-13 * ref  # from the same factors: measured equal
    assert gramians.gramian_factors(ms.models.dsms(201)).computed
    assert GramianStore(store.cache, salt="other").load(ms.models.dsms(200), first.options) is None
    assert store.key(fom, {**first.options, "shifts": np.array([-1.0 + 0j])}) is None
    assert len(list((store.cache.root / KIND).rglob("*.npz"))) == 2


def test_digest_follows_the_matrices():
    a, b = ms.models.dsms(50), ms.models.dsms(50)
    assert a.digest() == b.digest()
    c = ms.models.Index3Model(a.M, 1.0000001 * a.D, a.K, a.G, a.F, a.L)
    d = ms.models.Index3Model(a.M, a.D, a.K, a.G, a.F, 2 * a.L)
    assert len({a.digest(), c.digest(), d.digest()}) == 3


TOML = """
name = "gs"
title = "store"
norms = ["h2"]
[models]
tcom = "tcom:nc=20"
[methods.bt]
reducer = "bt"
[methods.fo]
reducer = "irka-fo"
[[scenes]]
name = "h2"
kind = "error_vs_r"
model = "tcom"
methods = ["bt", "fo"]
r = [2, 4]
measure = "h2"
"""


def test_a_shared_run_pays_the_factors_once(tmp_path):
    """Two workers, two readers of the factors (bt, irka-fo) and the H2 norms: one unit computes the
    factors, first; the reductions report them as shared work they did not pay."""
    from morsuite.studies import load_spec
    from morsuite.studies.batch import shared_compute
    from morsuite.studies.plan import build_plan

    (tmp_path / "gs.toml").write_text(TOML)
    study = load_spec(tmp_path / "gs.toml")
    cache = Cache(tmp_path / "cache")
    log = shared_compute([study], cache, jobs=2).record["log"]
    grams = [e for e in log if e["kind"] == "gramians"]
    assert len(grams) == 1
    assert all(e["start_s"] >= grams[0]["start_s"] + grams[0]["wall_s"] - 1e-6
               for e in log if e["unit"].startswith(("bt ", "irka-fo ", "h2 ")))
    assert len(list((cache.root / KIND).rglob("*.npz"))) == 1
    for g in build_plan(study).reduces.values():
        for r in g.rs:
            info = cache.get("reduction", g.keys[r])[1]["info"]
            assert info["lu_count_shared"] > 0 and info["lu_count"] < info["lu_count_shared"], (g.method.reducer, r)


def test_irka_waits_for_the_factors_unit_but_does_not_call_for_one(tmp_path):
    """The paper's IRKA reads the factors only to score an unconverged shortlist: beside a reader it
    waits for the model's factors' unit; alone (no reader, no H2 norm) no such unit is made."""
    from morsuite.studies import load_spec
    from morsuite.studies.batch import _units
    from morsuite.studies.plan import build_plan

    with_bt = TOML.replace('reducer = "irka-fo"', 'reducer = "irka"')
    alone = with_bt.replace('norms = ["h2"]', 'norms = []').replace('methods = ["bt", "fo"]', 'methods = ["fo"]')
    alone = alone.replace('measure = "h2"\n', '').replace('[methods.bt]\nreducer = "bt"\n', '')
    for text, expect in ((with_bt, True), (alone, False)):
        (tmp_path / "s.toml").write_text(text)
        units = _units([build_plan(load_spec(tmp_path / "s.toml"))], Cache(tmp_path / "cache"), {})
        grams = [u.id for u in units.values() if u.kind == "gramians"]
        irka = [u for u in units.values() if u.kind == "reduction" and u.args[1] == "irka"]
        assert irka and len(grams) == int(expect), (expect, sorted(units))
        assert all((set(grams) <= u.deps) for u in irka)


def test_a_free_floating_model_gets_no_factors_unit_work(store):
    """A model with rigid-body modes has a pole at 0 (its LR-ADI cannot converge): the factors' unit
    skips it, writes nothing, and leaves the readers to the flexible part's factors."""
    from morsuite.studies.gramian_store import compute_factors
    from morsuite.studies.task_common import model_of

    model_of.cache_clear()  # a model kept by an earlier test in this process would hold its factors already
    rec = compute_factors("dsms:g=40,free=true")
    assert "skipped" in rec and rec["lu_count"] == 0
    assert not list((store.cache.root).rglob("*.npz"))
    done = compute_factors("dsms:g=40")
    assert done["lu_count"] > 0 and done["converged"]
    assert len(list((store.cache.root / KIND).rglob("*.npz"))) == 1
