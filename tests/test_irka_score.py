"""IRKA without convergence returns the shortlisted stable iterate of smallest exact H2 error.

Reference: :func:`morsuite.analysis.h2_error` and :func:`morsuite.analysis.h2_norm` of
each shortlisted iterate, computed after the fact (the reducer's scorer never sees
them). No test depends on which iterates the chaotic iteration visits, or on whether
any of them is stable (that changes with the BLAS kernels).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import morsuite as ms
from morsuite.reducers.irka import score as irka_score


@pytest.fixture(scope="module")
def mimo():
    return ms.models.tcom(nc=50, constraints="curvature", io="points")


def _scored_run(monkeypatch, fom, r, **opts):
    """The reduction with the default scorer, the (rom, score) pairs it scored, and whether any
    iterate offered to the shortlist was stable."""
    from morsuite.reducers.irka.safeguards import Shortlist

    seen, offered = [], []
    original = irka_score.ExactH2Score.__call__
    add = Shortlist.add

    def spy(self, f, rom):
        value = original(self, f, rom)
        seen.append((rom, value))
        return value

    def spy_add(self, measure, it, stable, payload):
        offered.append(bool(stable))
        return add(self, measure, it, stable, payload)

    monkeypatch.setattr(irka_score.ExactH2Score, "__call__", spy)
    monkeypatch.setattr(Shortlist, "add", spy_add)
    with pytest.warns(ms.ConvergenceWarning, match="did not converge"):
        res = ms.reducers.make("irka", fom, maxit=30, tol=1e-12, **opts).reduce(r)
    return res, seen, any(offered)


@pytest.mark.parametrize("r", [6, 10])
def test_returned_iterate_has_the_smallest_exact_h2_error_of_the_shortlist(monkeypatch, mimo, r):
    # which iterates the chaotic run visits, and whether any is stable, depends on the machine's
    # rounding (with OpenBLAS's Prescott kernels no iterate at r = 10 is stable): the invariants
    # below hold either way, and the choice among several is also tested deterministically below
    res, seen, any_stable = _scored_run(monkeypatch, mimo, r)
    info, sg = res.info, res.info["safeguard"]
    assert info["converged"] is False
    if not any_stable:  # nothing to score: the iterate of smallest measure, unstable, and flagged
        assert not seen and sg["scored_by"] == "measure" and sg["score_lu_count"] == 0
        assert not res.rom.is_stable()
        return
    assert sg["scored_by"] == "iterate_score"
    assert 1 <= len(seen) <= info["options"]["shortlist"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        errors = [ms.analysis.h2_error(mimo, rom) for rom, _ in seen]
    # the score is the suite's one H2 evaluator's value: the error the tables report
    for e, (_, score) in zip(errors, seen):
        assert score == pytest.approx(e, rel=1e-12)
    returned = ms.analysis.h2_error(mimo, res.rom)
    assert res.rom.is_stable()
    assert returned <= min(errors) * (1 + 1e-8)
    assert returned == pytest.approx(min(errors), rel=1e-8)
    # the cost: at most one LU per real pole or conjugate pair of each scored iterate, counted, plus the
    # Gramian factors once per model (shared with bt and the norms)
    poles = [rom.poles() for rom, _ in seen]
    assert sg["score_lu_count"] == sum(rec["lu_count"] for rec in sg["score_records"])
    assert sg["score_lu_count"] <= sum(int(np.sum(p.imag >= 0)) for p in poles)
    assert sg["score_gramian_lu_count"] in (0, ms.linalg.gramians.gramian_factors(mimo).lu_count)  # once per model


def test_shortlist_chooses_the_smallest_exact_h2_error_not_the_smallest_measure(mimo):
    """Deterministic: stable candidates offered with measures that rank them in the wrong order."""
    from morsuite.reducers.irka.safeguards import Shortlist

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bt = ms.reducers.make("bt", mimo, form="vv")
        roms = [bt.reduce(r).rom for r in (2, 4, 6)]
        errors = [ms.analysis.h2_error(mimo, rom) for rom in roms]
    assert max(errors) > 1.1 * min(errors)  # the premise: the candidates differ
    order = np.argsort(errors)[::-1]  # the worst candidate gets the smallest measure
    shortlist = Shortlist(size=3)
    for rank, k in enumerate(order):
        shortlist.add(1e-3 * (rank + 1), int(k), True, (roms[k],))
    score = irka_score.ExactH2Score()
    it, payload, scores = shortlist.choose(lambda rom: score(mimo, rom))
    assert it == int(np.argmin(errors)) and payload[0] is roms[it]
    assert set(scores) == {0, 1, 2}
    # without a score the smallest measure wins: the worst of the three
    assert shortlist.choose()[0] == int(order[0])


def test_h2_score_reports_the_error_itself_when_the_gramian_factors_are_cached(mimo):
    rom = ms.reducers.make("bt", mimo).reduce(6).rom  # caches the factors on the model
    score = irka_score.ExactH2Score()
    value = score(mimo, rom)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = ms.analysis.h2_error(mimo, rom)
    assert score.records[0]["h2_error"] == pytest.approx(ref, rel=1e-12) and value == score.records[0]["h2_error"]
    assert score.records[0]["trusted"] and score.records[0]["floor"] <= 1e-4 * value
    assert score.gramian_lu_count == 0
    assert score.lu_count == score.records[0]["lu_count"] <= int(np.sum(rom.poles().imag >= 0))


def test_measure_ranking_costs_nothing_and_unstable_iterates_score_infinity(monkeypatch, mimo):
    res, seen, any_stable = _scored_run(monkeypatch, mimo, 10, shortlist_score="measure")
    sg = res.info["safeguard"]
    assert sg["scored_by"] == "measure" and sg["score_lu_count"] == 0 and not seen
    assert res.rom.is_stable() == any_stable  # unstable only where no iterate was stable
    unstable = ms.rom.SecondOrderROM(np.eye(2), -np.eye(2), np.eye(2), np.ones((2, mimo.m)), np.ones((mimo.p, 2)))
    score = irka_score.ExactH2Score()
    assert score(mimo, unstable) == np.inf and score.lu_count == 0


def test_bad_shortlist_score_is_refused():
    with pytest.raises(ms.OptionError, match="shortlist_score"):
        ms.reducers.make("irka", ms.models.dsms(50), shortlist_score="hinf")


def test_shared_lu_count_does_not_depend_on_what_ran_before_on_the_model():
    """``lu_count_shared`` is the LUs of the Gramian factors the scores relied on, whoever paid them
    (reducers.outcome): the same on a fresh model and on one whose factors an earlier call cached;
    only ``lu_count`` (what this call paid) and ``setup_reused`` differ, and the standalone count
    is the same. dsms(g=60), r = 2 caps and (here) scores its shortlist."""
    from morsuite.reducers.outcome import standalone_lu_count

    infos, gram = [], None
    for cached in (False, True):
        fom = ms.models.dsms(g=60)
        if cached:
            gram = ms.linalg.gramians.gramian_factors(fom).lu_count  # an earlier call's work
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            infos.append(ms.reducers.make("irka", fom, tol=1e-6).reduce(2).info)
    fresh, reused = infos
    # the same count and the same standalone cost whatever ran before on the model
    assert fresh["lu_count_shared"] == reused["lu_count_shared"]
    assert standalone_lu_count(fresh) == standalone_lu_count(reused) == fresh["lu_count"]
    assert fresh["safeguard"]["scored_by"] == reused["safeguard"]["scored_by"]
    if fresh["safeguard"]["scored_by"] != "iterate_score":  # no stable iterate to score (BLAS-dependent)
        assert fresh["lu_count_shared"] == 0 and fresh["lu_count"] == reused["lu_count"]
        return
    assert gram > 0 and fresh["lu_count_shared"] == gram
    assert not fresh.get("setup_reused") and reused["setup_reused"] is True
    assert fresh["lu_count"] == reused["lu_count"] + gram
