"""match_sets and the test assertions built on it (tests/support.py): planted permutations,
conjugate pairs whose real parts differ in the last bits, the bottleneck criterion, refusals,
and eigenvalue tolerances against planted spectra."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

import morsuite as ms
from morsuite.linalg.dense import match_sets
from support import assert_sets_close, eig_tolerance


def conjugate_closed(rng, pairs=5, real=2):
    z = -rng.uniform(0.1, 1, pairs) + 1j * rng.uniform(0.5, 5, pairs)
    return np.concatenate([z, np.conj(z), -rng.uniform(0.1, 1, real)])


def test_recovers_a_planted_permutation():
    rng = np.random.default_rng(0)
    a = conjugate_closed(rng)
    noise = 1e-9 * (rng.standard_normal(a.size) + 1j * rng.standard_normal(a.size))
    p = rng.permutation(a.size)
    b = (a + noise)[p]  # b[j] = a[p[j]] + noise[p[j]]
    perm, dist = match_sets(a, b)
    assert np.array_equal(p[perm], np.arange(a.size))
    assert np.allclose(dist, np.abs(noise), rtol=1e-6, atol=0)
    perm_r, dist_r = match_sets(a, b, scale="relative")
    assert np.array_equal(perm_r, perm)
    assert np.allclose(dist_r, dist / np.maximum(np.abs(a), np.abs(b[perm])), rtol=1e-12, atol=0)


def test_conjugate_pairs_stay_together_where_sorting_splits_them():
    """The K6 situation: QZ returns a pair whose real parts differ in the last bit; sorting by
    real part then pairs +imag with -imag. Matching pairs each member with its own conjugate."""
    x, y = -347.10660708046333, 58303178.37960179
    a = np.array([complex(np.nextafter(x, -np.inf), y), complex(x, -y), -275.6 + 4.99e7j, -275.6 - 4.99e7j])
    b = np.array([complex(x - 0.5, -y + 2e-4), complex(x - 0.5, y - 2e-4), -279.9 - 4.99e7j, -279.9 + 4.99e7j])
    assert np.max(np.abs(np.sort_complex(a) - np.sort_complex(b))) > y  # the fault being fixed
    perm, dist = match_sets(a, b)
    assert np.all(np.sign(a.imag) == np.sign(b[perm].imag)) and dist.max() < 5
    # a property over random conjugation-closed sets b near a (perturbed by up to a third of the
    # smallest gap, pairs perturbed as pairs), shuffled: the optimum is the planted matching, and
    # it maps conj(a_i) to conj(b[perm[i]])
    rng = np.random.default_rng(1)
    for _ in range(50):
        a = conjugate_closed(rng, pairs=6, real=3)
        gap = np.min(np.abs(a[:, None] - a[None, :]) + np.diag(np.full(a.size, np.inf)))
        dz = gap / 3 * rng.uniform(0, 1, 9) * np.exp(2j * np.pi * rng.uniform(0, 1, 9))
        b = a + np.concatenate([dz[:6], np.conj(dz[:6]), dz[6:].real])
        p = rng.permutation(a.size)
        perm, _ = match_sets(a, b[p])
        assert np.array_equal(p[perm], np.arange(a.size))
        for i in range(a.size):
            k = int(np.argmin(np.abs(a - np.conj(a[i]))))
            assert b[p][perm[k]] == np.conj(b[p][perm[i]])


def test_bottleneck_not_sum_decides():
    """A minimal sum can hide one large mismatch: the sets agree within 1.5 by one matching."""
    a = np.array([2 + 3j, 2 + 2j, 4 + 2j])
    b = np.array([3 + 2j, 2 + 2j, 1 + 1j])
    cost = np.abs(a[:, None] - b[None, :])
    i, j = linear_sum_assignment(cost)
    assert cost[i, j].max() > 2.2  # the min-sum matching
    perm, dist = match_sets(a, b)
    assert dist.max() == pytest.approx(np.sqrt(2), rel=1e-15)
    assert_sets_close(a, b, atol=1.5)
    with pytest.raises(AssertionError, match=r"1 of 3 not within tolerance.*worst"):
        assert_sets_close(a, b, atol=1.3, what="poles")


def test_per_element_scale_and_exact_zero():
    a = np.array([0.0, 1e-3, 1e3])
    b = np.array([1e3 * (1 + 1e-9), 0.0, 1e-3 * (1 + 1e-9)])
    perm, dist = match_sets(a, b, scale=1e-8 * np.abs(b))
    assert list(perm) == [1, 2, 0] and dist.max() < 0.2 + 1e-6  # 0 matches 0 under a zero scale
    assert_sets_close(a, b, rtol=1e-8)
    with pytest.raises(AssertionError, match="HSVs"):
        assert_sets_close(a, b, rtol=1e-10, what="HSVs")
    with pytest.raises(AssertionError, match="2 computed against 3"):
        assert_sets_close(a[:2], b)


@pytest.mark.parametrize("args, match", [
    (([1.0, 2.0], [1.0]), "same size"),
    (([1.0, np.nan], [1.0, 2.0]), "a has non-finite"),
    (([[1.0]], [1.0]), "a must be a 1-D"),
    ((["x"], [1.0]), "a must be a 1-D numeric"),
    (([1.0], [1.0], [-1.0]), "scale must be"),
    (([1.0], [1.0], "absolute"), "scale must be"),
    (([1.0, 2.0], [1.0, 2.0], [1.0]), "scale must be"),
])
def test_bad_input_is_refused(args, match):
    with pytest.raises(ms.InputError, match=match):
        match_sets(*args)


def test_empty_sets():
    perm, dist = match_sets([], [])
    assert perm.size == dist.size == 0


def test_eig_tolerance_on_planted_spectra():
    """Planted eigenvalues of V diag(lam) V^-1: the computed ones are within the bound, and the
    bound is tight enough to fail a perturbation of 100 times it; it grows with cond(V)."""
    rng = np.random.default_rng(2)
    re, im = -rng.uniform(0.1, 1, 4), rng.uniform(1, 10, 4)
    lam = np.concatenate([re + 1j * im, re - 1j * im])
    B = np.zeros((8, 8))  # real block form: 2 x 2 blocks [[re, im], [-im, re]]
    for k in range(4):
        B[2 * k:2 * k + 2, 2 * k:2 * k + 2] = [[re[k], im[k]], [-im[k], re[k]]]
    tols = []
    for cond in (1.0, 1e6):
        U = np.linalg.qr(rng.standard_normal((8, 8)))[0]
        W = np.linalg.qr(rng.standard_normal((8, 8)))[0]
        V = U @ np.diag(np.logspace(0, -np.log10(cond), 8)) @ W
        A = V @ B @ np.linalg.inv(V)
        got, tol = eig_tolerance(A)
        assert_sets_close(got, lam, atol=tol, what="eigenvalues")
        assert_sets_close(np.linalg.eigvals(A), lam, atol=tol, what="eigenvalues (geev)")
        with pytest.raises(AssertionError):
            assert_sets_close(got + 100 * tol.max(), lam, atol=tol)
        tols.append(tol.max())
    assert tols[0] < 1e-12 and tols[1] > 1e3 * tols[0]
    # a pencil (A, E = I): the same condition numbers, and E's backward error adds |lam| ||E||
    got_p, tol_p = eig_tolerance(A, np.eye(8))
    assert_sets_close(got_p, lam, atol=tol_p)
    perm = match_sets(got_p, got)[0]
    norm_a = np.linalg.norm(A, 2)
    assert np.allclose(tol_p, tol[perm] * (norm_a + np.abs(got_p)) / norm_a, rtol=1e-3)
