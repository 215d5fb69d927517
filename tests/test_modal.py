"""The ``modal`` reducer against dense references: the undamped constrained eigenfrequencies from a
null-space basis of G, the static response T(0), the structure of the projection."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.errors import InputError, OptionError
from support import assert_sets_close, dense_modes, orthonormality_error

RTOL = 1e-10


def undamped(rom):
    return np.sqrt(sla.eigvalsh(rom.K, rom.M))


MODELS = {
    "dsms": lambda: ms.models.dsms(g=100),
    "tcom": lambda: ms.models.tcom(nc=40),
    "fem_block": lambda: ms.models.fem_block(400),
    "fem_beam": lambda: ms.models.fem_beam(12, 2, 2),
    "mimo": lambda: ms.models.random_constrained(n1=60, n2=3, m=2, p=3, seed=1),
}


@pytest.fixture(scope="module", params=sorted(MODELS))
def case(request):
    fom = MODELS[request.param]()
    return fom, dense_modes(fom)


def _contains(found, expected, rtol, what):
    """Each expected value has a found one within rtol (matched by tolerance, not by position)."""
    found = np.asarray(found)
    for w in np.asarray(expected):
        d = np.min(np.abs(found - w)) / w
        assert d <= rtol, f"{what}: {w!r} not found within {rtol:g} (nearest at relative {d:.2e})"


def test_lowest_modes_equal_the_dense_reference(case):
    fom, (w_ref, _) = case
    r = 10
    res = ms.reducers.make("modal", fom, static_correction=False).reduce(r)
    rom = res.rom
    assert rom.order == r and res.info["modes"] == r and res.info["static_columns"] == 0
    assert_sets_close(undamped(rom), w_ref[:r], rtol=RTOL, what="undamped eigenfrequencies")
    assert_sets_close(res.info["omega"], w_ref[:r], rtol=RTOL, what="info omega")
    V = rom.basis
    err, tol = orthonormality_error(V, fom.M)
    assert err <= tol, (err, tol)
    assert np.abs(rom.K - np.diag(np.diag(rom.K))).max() < 1e-10 * np.abs(rom.K).max()
    assert np.abs(fom.G @ V).max() < 1e-10 * np.abs(V).max() * max(1.0, abs(fom.G).max())
    assert res.info["lu_count"] == 1 and res.info["converged"] and res.info["max_residual"] < 1e-10


def test_static_correction_matches_T0_and_keeps_the_modes(case):
    fom, (w_ref, _) = case
    red = ms.reducers.make("modal", fom, static_correction=True)
    T0 = fom.transfer(0.0)
    for r in (6, 12):
        res = red.reduce(r)
        rom = res.rom
        k = r - fom.m
        assert res.info["static_columns"] == fom.m and res.info["modes"] == k
        assert np.abs(rom.transfer(0.0) - T0).max() <= RTOL * np.abs(T0).max()
        _contains(undamped(rom), w_ref[:k], RTOL, "modes kept beside the static block")
        V = rom.basis
        err, tol = orthonormality_error(V, fom.M)   # (was a fixed 1e-10)
        assert err <= tol, (err, tol)
        assert np.abs(rom.K - np.diag(np.diag(rom.K))).max() < 1e-9 * np.abs(rom.K).max()
    # the second call reused the modes' LU and the static solve
    assert res.info["lu_count"] == 0 and res.info["setup_reused"] and res.info["lu_count_shared"] >= 1


def test_band_selection_takes_every_mode_in_the_band():
    fom = ms.models.tcom(nc=40)
    w_ref, _ = dense_modes(fom)
    band = (0.5 * (w_ref[3] + w_ref[4]), 0.5 * (w_ref[9] + w_ref[10]))  # modes 4..9 inside
    res = ms.reducers.make("modal", fom, selection="band", band=list(band), static_correction=False).reduce(6)
    assert_sets_close(res.info["omega"], w_ref[4:10], rtol=RTOL, what="band modes")
    res8 = ms.reducers.make("modal", fom, selection="band", band=list(band), static_correction=False).reduce(8)
    _contains(res8.info["omega"], w_ref[4:10], RTOL, "band modes first")


def test_dominance_selection_against_dense_dominance():
    fom = ms.models.dsms(g=100)
    w_ref, Y = dense_modes(fom)
    r, pool = 5, 2.0
    res = ms.reducers.make("modal", fom, selection="dominance", static_correction=False, pool=pool).reduce(r)
    # independent dominance from the dense modes (M-normalised by eigh): the r largest among the pool
    n = int(np.ceil(pool * r))
    Yp, wp = Y[:, :n], w_ref[:n]
    zeta = np.einsum("ij,ij->j", Yp, fom.D @ Yp) / (2 * wp)
    w = np.clip(wp, *fom.band)
    d = np.linalg.norm(fom.L @ Yp, axis=0) * np.linalg.norm(fom.F.T @ Yp, axis=0) / \
        np.abs(wp ** 2 - w ** 2 + 2j * zeta * wp * w)
    top = np.argsort(-d)[:r]
    gap = np.sort(d)[::-1]
    assert gap[r - 1] > 1.01 * gap[r], "the test needs a clear r-th dominance"
    assert_sets_close(res.info["omega"], wp[top], rtol=RTOL, what="dominant modes")


@pytest.mark.parametrize("name", sorted(MODELS))
def test_make_reduce_compare_like(name):
    fom = MODELS[name]()
    red = ms.reducers.make("modal", fom)
    for r in (4, 8):
        res = red.reduce(r)
        assert res.rom.order == r and res.info["stable"] and res.info["status"] == "direct"
        assert res.info["r"] == r and res.info["states"] == 2 * r
        H = fom.freqresp([fom.band[0], np.sqrt(fom.band[0] * fom.band[1])])
        assert np.all(np.isfinite(res.rom.freqresp([fom.band[0]])))
        assert H.shape[1:] == res.rom.freqresp([1.0]).shape[1:]


def test_bad_input_is_refused_naming_the_argument():
    fom = ms.models.dsms(g=20)
    with pytest.raises(OptionError, match="'selection' parameter of Modal"):
        ms.reducers.make("modal", fom, selection="highest")
    with pytest.raises(InputError, match="'band' parameter of Modal.*empty"):
        ms.reducers.make("modal", fom, band=[1.0, 0.5])
    with pytest.raises(InputError, match=r"r = 19 exceeds .*n1 - n2 - 1 = 18"):
        ms.reducers.make("modal", fom).reduce(19)
    with pytest.raises(OptionError, match="unknown option"):
        ms.reducers.make("modal", fom, modes=3)
    mimo = MODELS["mimo"]()
    with pytest.raises(InputError, match="r = 1 is smaller than the m = 2 static-correction columns"):
        ms.reducers.make("modal", mimo).reduce(1)


def test_free_floating_model_keeps_the_rigid_mode_and_corrects_the_flexible_part():
    import scipy.sparse as sp
    n = 30
    K = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1], format="lil")
    K[0, 0] = K[n - 1, n - 1] = 1.0  # free-free chain: one rigid-body mode
    K = K.tocsr()
    M = sp.identity(n, format="csr")
    G = sp.csr_matrix(([1.0, -1.0], ([0, 0], [3, 4])), shape=(1, n))  # a tie, not a clamp
    F = np.zeros((n, 1)); F[0] = 1.0
    fom = ms.models.Index3Model(M, 0.01 * K, K, G, F, F.T, band=(0.01, 2.0))
    w_ref, shapes = dense_modes(fom)
    res = ms.reducers.make("modal", fom).reduce(5)  # the flexible part (models.rigid), the rigid mode added back
    assert res.info["rigid_modes"]["count"] == 1 and res.rom.order == 6
    assert res.info["static_columns"] == 1 and res.info["sigma"] == 0
    # the reduced model's undamped frequencies: the rigid mode at 0, then the lowest flexible ones
    w_rom = np.sqrt(np.abs(sla.eigvalsh(res.rom.K, res.rom.M)))
    assert w_rom.min() == 0.0
    assert_sets_close(res.info["omega"], w_ref[1:1 + len(res.info["omega"])], rtol=1e-8, atol=1e-7,
                      what="flexible modes of a free-floating model")
    # static correction of the flexible part: T_flex(0) from the dense flexible modes
    Zf = shapes[:, 1:]
    Tflex0 = fom.L @ Zf @ np.diag(1 / w_ref[1:] ** 2) @ Zf.T @ fom.F
    assert np.allclose(res.rom.flexible.transfer(0.0), Tflex0, rtol=1e-10, atol=0)


def test_partial_convergence_of_the_modes_is_a_status(monkeypatch):
    """ARPACK converging 3 of the 7 modes reduce(8) needs (planted) and a real run capped at one restart:
    status 'partial', converged False, the warning in info, a reduced model of the modes that converged."""
    import scipy.sparse.linalg as spla

    from morsuite.errors import ConvergenceWarning
    from morsuite.linalg import eigen

    fom = ms.models.dsms(g=100)
    w_ref, _ = dense_modes(fom)
    real = spla.eigsh

    def eigsh(*args, **kwargs):  # the second, fourth, ... nearest pairs converged
        lam, X = real(*args, **kwargs)
        raise spla.ArpackNoConvergence("planted", lam[1::2], X[:, 1::2])

    with monkeypatch.context() as mp:
        mp.setattr(eigen.spla, "eigsh", eigsh)
        with pytest.warns(ConvergenceWarning) as said:
            res = ms.reducers.make("modal", fom).reduce(8)
    assert any("converged 3 of 7 modes" in str(w.message) for w in said)
    info = res.info
    assert info["status"] == "partial" and info["converged"] is False and info["modes"] == 3
    assert res.rom.order == 4 and info["r"] == 4  # 3 modes and the static column
    assert "converged 3 of 7" in info["status_reason"]
    assert any("converged 3 of 7" in w for w in info["warnings"])
    _contains(info["omega"], w_ref[1:7:2], RTOL, "the planted converged modes")
    with pytest.warns(ConvergenceWarning):
        capped = ms.reducers.make("modal", fom, maxiter=1).reduce(8)
    assert capped.info["status"] == "partial" and not capped.info["converged"] and capped.info["warnings"]
    assert capped.info["options"]["maxiter"] == 1


def test_cutoff_selection_keeps_every_mode_up_to_the_factor():
    """selection='cutoff' (the engineers' rule): the modes below cutoff x the band's upper end, no more; r caps them."""
    fom = ms.models.tcom(nc=30)
    w_ref, _ = dense_modes(fom)
    w2 = 0.4
    for c in (1.0, 2.5):
        expect = np.sort(w_ref[(w_ref > 0) & (w_ref <= c * w2)])
        red = ms.reducers.make("modal", fom, selection="cutoff", cutoff=c, band=[0.01, w2], static_correction=False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = red.reduce(fom.order - 1)
        assert_sets_close(np.asarray(res.info["omega"]), expect, rtol=1e-8, what="modes below the cutoff")
        assert res.rom.order == expect.size
    capped = ms.reducers.make("modal", fom, selection="cutoff", cutoff=2.5, band=[0.01, w2],
                              static_correction=False).reduce(3)
    assert capped.rom.order == 3  # the three lowest (sorted to select them, matched to compare them)
    assert_sets_close(np.asarray(capped.info["omega"]), expect[:3], rtol=1e-8, what="the three lowest modes")
