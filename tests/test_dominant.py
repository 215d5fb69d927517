"""Modal truncation by band dominance ("dominant", issue 46 item 2): the poles SAQDPA converged against the dense
quadratic eigenproblem on ker G (poles, residues, dominance), the static correction, structure and stability,
the poles kept by the reduced model, the tolerance route's estimate against the true error, the LU budget on a
pole cluster and refused input."""

from __future__ import annotations


import numpy as np
import pytest
import scipy.sparse as sp

import morsuite as ms
from morsuite.linalg.dense import sigma_max
from morsuite.reducers.base import as_complex
from morsuite.reducers.dominant.qdpa import band_distance
from morsuite.utils import blas_threads
from support import dense_reduced
from test_adaptive import _reduce as reduce_with
from test_adaptive import dense_curve, dense_transfer

MODELS = {"tcom": lambda: ms.models.tcom(nc=40), "fem_block": lambda: ms.models.fem_block(300)}


@pytest.fixture(scope="module")
def models():
    return {k: f() for k, f in MODELS.items()}


def _reduce(fom, r, **opts):
    return reduce_with(fom, r, "dominant", **opts)


def dense_poles(ref):
    """Poles (Im >= 0) of the dense system on ker G (numpy eig of the companion form) and, per pole, the residue of
    its eigenspace: (L X)(X^T (2 lam M + D) X)^-1 (X^T F) over the eigenvectors X of the poles equal to it (to 1e-7;
    symmetric M, D, K: the left eigenvectors are the right ones)."""
    M, D, K, F, L = ref
    n = M.shape[0]
    with blas_threads(1):
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, D)]])
        lam, X = np.linalg.eig(A)
    keep = lam.imag >= 0
    lam, X = lam[keep], X[:n, keep]
    R = []
    for t in lam:
        Xg = X[:, np.abs(lam - t) <= 1e-7 * abs(t)]
        R.append((L @ Xg) @ np.linalg.solve(Xg.T @ ((2 * t) * (M @ Xg) + D @ Xg), Xg.T @ F))
    return lam, np.array(R)


@pytest.mark.parametrize("name", list(MODELS))
def test_converged_poles_residues_and_dominance_against_the_dense_problem(models, name):
    fom = models[name]
    ref = dense_reduced(fom)
    lam, R = dense_poles(ref)
    _, res = _reduce(fom, 10)
    info = res.info
    poles = as_complex(info["poles"])
    assert poles.size >= 3
    for k, p in enumerate(poles):
        j = int(np.argmin(np.abs(lam - p)))
        assert abs(lam[j] - p) <= 1e-7 * abs(p), (p, lam[j])
        assert info["pole_residuals"][k] <= 1e-8
        # a multiple pole's residue is the sum over its eigenspace (any basis of it splits it its own way):
        # compare sums over the group of equal poles, where the reducer kept as many shapes as the dense one has
        mine = np.abs(poles - p) <= 1e-7 * abs(p)
        dense = np.abs(lam - p) <= 1e-7 * abs(p)
        if mine.sum() == dense.sum():
            got = as_complex(info["residues"][k])  # a multiple pole's: its eigenspace's, in each member
            want = R[j]
            # a residue from a shape of residual 1e-8: its error is the residual over the gap to the next pole
            assert np.abs(got - want).max() <= 1e-4 * np.abs(want).max()
            if dense.sum() == 1:
                d = sigma_max(R[j][None])[0] / band_distance([lam[j]], fom.band)[0]
                assert info["dominance"][k] == pytest.approx(d, rel=1e-4)
    assert any(np.sum(np.abs(lam - p) <= 1e-7 * abs(p)) == 1 for p in poles)  # some simple pole was checked
    # the reduced model keeps every chosen pole (the basis holds its shape)
    mu = res.rom.poles()
    for p in poles:
        assert np.min(np.abs(mu - p)) <= 1e-6 * abs(p)


@pytest.mark.parametrize("name", list(MODELS))
def test_static_correction_structure_and_stability(models, name):
    fom = models[name]
    ref = dense_reduced(fom)
    _, res = _reduce(fom, 8)
    rom = res.rom
    T0 = dense_transfer(ref, [0.0])[0]
    assert np.abs(rom.transfer(0.0) - T0).max() <= 1e-9 * np.abs(T0).max()
    for X in (rom.M, rom.K):
        assert np.array_equal(X, X.T) and np.linalg.eigvalsh(X).min() > 0
    assert rom.is_stable() and res.info["stable"] and res.info["static_columns"] == fom.m
    assert res.info["lu_count"] == len(res.info["points"]) and as_complex(res.info["points"])[0] == 0


def test_tolerance_route_estimate_against_the_true_error(models):
    fom = models["tcom"]
    ref = dense_reduced(fom)
    _, res = _reduce(fom, fom.order, tol=1e-2)
    info = res.info
    assert info["status"] == "converged" and info["estimate_max"] <= 1e-2
    grid = np.asarray(info["estimate_grid"])
    H = dense_curve(ref, 1j * np.concatenate([grid, np.geomspace(*fom.band, 200)]))
    peak = sigma_max(H[grid.size:]).max()
    true = sigma_max(H[:grid.size] - dense_curve((res.rom.M, res.rom.D, res.rom.K, res.rom.F, res.rom.L),
                                                 1j * grid)) / peak
    assert 0.1 <= info["estimate_max"] / true.max() <= 10, (info["estimate_max"], true.max())


def test_budget_on_a_pole_cluster():
    fom = ms.models.dsms(g=60)  # its poles form one cluster: Newton on the Ritz values converges slowly
    with pytest.warns(ms.errors.ConvergenceWarning, match="max_lus = 4"):
        res = ms.reducers.make("dominant", fom, tol=1e-3, max_lus=4).reduce(fom.order)
    assert res.info["status"] == "budget" and res.info["converged"] is False and res.info["lu_count"] == 4


def test_non_symmetric_model_is_refused(models):
    fom = models["tcom"]
    D = fom.D.tolil()
    D[0, 1] += 1.0
    bad = ms.models.Index3Model(fom.M, sp.csr_matrix(D), fom.K, fom.G, fom.F, fom.L, band=fom.band)
    with pytest.raises(ms.errors.OptionError, match="symmetric"):
        ms.reducers.make("dominant", bad)
