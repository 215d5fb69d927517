"""Property-based stress tests: invariants on random constrained models, not snapshots.

Each property draws random models from ``ms.models.random_constrained`` (n1 up
to 120 so that an example takes well under a second) and runs one check of
``morsuite.stress`` (the same functions the ``python -m morsuite.stress``
runner uses). An outcome is acceptable when it is ``pass``, ``not-converged``
(converged=False with a ConvergenceWarning) or ``refused`` (a documented
MorsuiteError). A failure that matches a known bug (``morsuite.stress.KNOWN_BUGS``,
each with a strict-xfail reproducer in ``test_known_bugs.py``) is reported as
a :class:`KnownBugWarning` instead of failing the property, so that a new
failure stands out; once a bug is fixed its reproducer XPASSes and fails.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg as sla
from hypothesis import event, given
from hypothesis import strategies as st

import morsuite as ms
from morsuite import stress as S
from morsuite.stress.outcomes import _run_reducer
from stress_support import STRESS, model_params

pytestmark = pytest.mark.stress

ACCEPTED = ("pass", "not-converged", "refused")


class KnownBugWarning(UserWarning):
    """A property example failed in a way already reported (see test_known_bugs.py)."""


def accept(out: S.Outcome, recheck=None):
    """Assert that ``out`` is acceptable, or attributable to a known bug (then warn)."""
    event(f"outcome: {out.outcome}")
    if out.outcome in ACCEPTED:
        return
    bug = S.known_bug(out)
    if bug is None and out.outcome == "FAIL-silent" and recheck is not None:
        key = S.attribute_silent(recheck)
        bug = next((b for b in S.KNOWN_BUGS if b.key == key), None)
    if bug is not None:
        warnings.warn(f"known bug {bug.key}: {out.detail}", KnownBugWarning)
        return
    raise AssertionError(f"{out.outcome}: {out.detail} (metrics {out.metrics})")



# -- the generator ---------------------------------------------------------------
@STRESS
@given(kw=model_params(n1_max=80))
def test_generator_invariants(kw):
    """SPD sparse M and K, symmetric PSD D, full-row-rank G, n2 <= n1/2, deterministic, band a decade wide."""
    fom = ms.models.random_constrained(**kw)
    assert (fom.n1, fom.n2, fom.m, fom.p) == (kw["n1"], kw["n2"], kw["m"], kw["p"])
    assert fom.n2 <= fom.n1 // 2
    M, D, K = (X.toarray() for X in (fom.M, fom.D, fom.K))
    for name, X in (("M", M), ("D", D), ("K", K)):
        assert np.array_equal(X, X.T), f"{name} is not symmetric"
    assert fom.M.nnz <= 3 * fom.n1 and fom.K.nnz < fom.n1 ** 2 / 2, "M or K not sparse"
    lam = sla.eigh(K, M, eigvals_only=True)
    assert lam[0] > 0 and np.linalg.eigvalsh(M)[0] > 0
    assert np.linalg.eigvalsh(D)[0] >= -1e-12 * np.abs(D).max()
    if fom.n2:
        sv = np.linalg.svd(fom.G.toarray(), compute_uv=False)
        assert sv[-1] > 1e-8 * sv[0], "G is not of full row rank"
    w = np.sqrt(lam)
    lo, hi = fom.band
    # a decade beyond the eigenfrequencies (the low end is an eigsh estimate to 1e-3)
    assert lo <= w[0] / 9.9 and hi >= 9.9 * w[-1], (fom.band, w[0], w[-1])
    again = ms.models.random_constrained(**kw)
    for a, b in ((fom.M, again.M), (fom.D, again.D), (fom.K, again.K), (fom.G, again.G)):
        assert (a != b).nnz == 0
    assert np.array_equal(fom.F, again.F) and np.array_equal(fom.L, again.L)
    if kw["damping"] == "rayleigh" and kw["zeta"] > 0:
        # modal damping ratio zeta_i = a/(2 w_i) + b w_i / 2 is convex in w_i and equals zeta
        # at the (estimated) ends of the spectrum, so no mode is damped above zeta
        phi = sla.eigh(K, M)[1]
        ratio = np.diag(phi.T @ D @ phi) / (2 * w * np.diag(phi.T @ M @ phi))
        assert np.max(ratio) <= kw["zeta"] * 1.01


def test_generator_refuses_bad_parameters():
    with pytest.raises(ms.InputError, match=r"n2 must be an integer in \[0, 5\]"):
        ms.models.random_constrained(n1=10, n2=6)
    with pytest.raises(ms.InputError, match=r"damping must be one of"):
        ms.models.random_constrained(damping="viscous")
    with pytest.raises(ms.InputError, match=r"mass_unit must be finite"):
        ms.models.random_constrained(mass_unit=0.0)


def test_generator_in_catalog_and_namespace():
    assert "random" in ms.models.available()
    fom = ms.models.parse("random:n1=30,n2=3,m=2,p=2,seed=4,damping=dashpots")
    assert (fom.n1, fom.n2, fom.m, fom.p) == (30, 3, 2, 2)
    assert "random_constrained" in ms.models.__all__


# -- reducers: finite ROM or documented error, consistent info, Hermite conditions -----
#: options that keep an example well under a second (bt-fl: a fixed 16-node rule over the band)
_FAST = {"irka": {"maxit": 30}, "irka-projected": {"maxit": 30}, "bt": {"maxiter": 150}, "modal": {},
         "krylov": {}, "bt-fl": {"nodes": 16}, "adaptive": {"max_lus": 8},
         "dominant": {"max_lus": 8}}
#: the methods whose examples take 0.5 to 1.2 s each (6 to 15 s of CPU for the default 12): the slow set
_SLOW = ("irka", "bt-fl")


@pytest.mark.parametrize("method", [pytest.param(m, marks=pytest.mark.slow) if m in _SLOW else m for m in _FAST])
def test_reducer_returns_finite_rom_or_documented_error(method):
    if method not in ms.reducers.available():
        pytest.skip(f"reducer {method!r} is not registered yet")

    @STRESS
    @given(kw=model_params(), r=st.integers(1, 12))
    def prop(kw, r):
        fom = ms.models.random_constrained(**kw)
        r = min(r, fom.order)
        opts = _FAST[method]
        out = S.check_reduction(fom, method, r, opts)
        accept(out, lambda: S.check_reduction(ms.models.random_constrained(**kw), method, r, opts))

    prop()


@STRESS
@given(kw=model_params(n1_max=100, spreads=(0.0, 3.0), units=False, zeta_range=(-3.0, 0.0)),
       r=st.integers(2, 8))
def test_converged_irka_satisfies_hermite_conditions(kw, r):
    """T(a) b, c^T T(a), c^T T'(a) b of the full model and the ROM agree at every shift a (full order only)."""
    from morsuite.reducers.base import as_complex

    fom = ms.models.random_constrained(**kw)
    r = min(r, fom.order)
    res, exc, W = _run_reducer("irka", fom, r, {"maxit": 60})
    if exc is not None:
        accept(S.classify_exception(fom, exc, W))
        return
    info = res.info
    if not info["converged"]:  # then it said how it ended and warned (reducers.outcome)
        assert info["status"] in ("cap", "cycle", "stalled") and any(w.category is ms.ConvergenceWarning for w in W)
    if not (info["converged"] and info["r"] == info["r_requested"]):
        event("not applicable (not converged or rank capped)")
        return
    event("checked")
    err, tol = S.hermite_error(fom, res.rom, as_complex(info["shifts"]), as_complex(info["b"]),
                               as_complex(info["c"]))
    assert err <= tol, f"Hermite conditions violated: {err:.2e} > {tol:.1e}"


# -- the two IRKAs agree ----------------------------------------------------------------
@STRESS
@given(kw=model_params(n1_max=80), r=st.integers(1, 8), maxit=st.integers(1, 3), seed=st.integers(0, 2**16))
def test_irka_and_projected_irka_agree(kw, r, maxit, seed):
    fom = ms.models.random_constrained(**kw)
    r = min(r, fom.order)
    shifts = S.given_shifts(fom, r, np.random.default_rng(seed))
    out = S.check_agreement(fom, r, maxit, shifts)
    accept(out, lambda: S.check_agreement(ms.models.random_constrained(**kw), r, maxit, shifts))


# -- transfer function: saddle-point solve against a dense null-space basis --------------
@STRESS
@given(kw=model_params(n1_max=80), x=st.floats(0, 1), y=st.floats(0, 1), z=st.floats(0, 1))
def test_saddle_transfer_matches_dense_nullspace(kw, x, y, z):
    fom = ms.models.random_constrained(**kw)
    lo, hi = np.log10(fom.band[0]), np.log10(fom.band[1])
    w = [10 ** (lo + t * (hi - lo)) for t in (x, y, z)]
    pts = [1j * w[0], complex(w[1], w[2]), complex(w[2], 0.0)]
    out = S.check_nullspace(fom, pts)
    accept(out, lambda: S.check_nullspace(ms.models.random_constrained(**kw), pts))


# -- invariance under the row order and scaling of G ------------------------------------
@STRESS
@given(kw=model_params(n1_max=80), r=st.integers(1, 8), maxit=st.integers(1, 3), seed=st.integers(0, 2**16))
def test_results_do_not_depend_on_row_order_or_scaling_of_G(kw, r, maxit, seed):
    fom = ms.models.random_constrained(**kw)
    r = min(r, fom.order)
    out = S.check_g_invariance(fom, r, np.random.default_rng(seed), maxit=maxit)
    accept(out, lambda: S.check_g_invariance(ms.models.random_constrained(**kw), r,
                                             np.random.default_rng(seed), maxit=maxit))


# -- first-order BT and its bound --------------------------------------------------------
def test_bt_never_exceeds_its_error_bound():
    if "bt" not in ms.reducers.available():
        pytest.skip("reducer 'bt' is not registered yet")

    @STRESS
    @given(kw=model_params(n1_max=80, spreads=(0.0, 3.0)), r=st.integers(1, 8))
    def prop(kw, r):
        fom = ms.models.random_constrained(**kw)
        out = S.check_bt_bound(fom, min(r, fom.order), {"maxiter": 150})
        accept(out)

    prop()
