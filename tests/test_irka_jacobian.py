"""The closed-form Jacobian of the SISO first-order IRKA map against a modal surrogate
(morsuite.reducers.irka.jacobian), checked against central differences of the map itself,
and Newton's method with it: its fixed point against the dense Hermite conditions."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.reducers.irka.surrogate import Chart, ModalSurrogate, SurrogateMap, _jacobian, iterate, newton_fixed_point


def _surrogate(seed=3, n=16, m=1, p=1):
    """A stable model with lightly damped, well separated pole pairs (a similarity keeps it non-modal)."""
    rng = np.random.default_rng(seed)
    w = np.linspace(1, 8, n // 2)
    a = 0.05 * w + 0.1
    A = np.zeros((n, n))
    for i in range(n // 2):
        A[2 * i:2 * i + 2, 2 * i:2 * i + 2] = [[-a[i], w[i]], [-w[i], -a[i]]]
    T = rng.standard_normal((n, n)) / 4 + np.eye(n)
    rom = ms.rom.FirstOrderROM(None, np.linalg.solve(T, A @ T), rng.standard_normal((n, m)),
                               rng.standard_normal((p, n)))
    return rom, ModalSurrogate(rom)


def _point(smap, m=1, p=1, steps=1):
    rng = np.random.default_rng(4)
    up = np.array([0.3 + 1.5j, 0.5 + 4.0j, 0.6 + 6.5j])
    alpha = np.concatenate([up, up.conj(), [2.0]])
    b = rng.standard_normal((3, m)) + 1j * rng.standard_normal((3, m))
    c = rng.standard_normal((3, p)) + 1j * rng.standard_normal((3, p))
    bdir = np.vstack([b, b.conj(), rng.standard_normal((1, m))])
    cdir = np.vstack([c, c.conj(), rng.standard_normal((1, p))])
    return iterate(smap, alpha, bdir, cdir, maxit=steps, tol=0.0, plain=100)["last"]


@pytest.mark.parametrize("m, p, steps", [(1, 1, 1), (2, 3, 6), (1, 3, 5)], ids=["siso", "mimo-2x3", "simo-1x3"])
def test_closed_form_jacobian_matches_central_differences(m, p, steps):
    _, sur = _surrogate(m=m, p=p)
    smap = SurrogateMap(sur, (0.1, 10.0))
    nxt = _point(smap, m, p, steps)
    chart = Chart.at(*nxt)
    x = chart.encode(*nxt)
    F, _ = smap.residual(chart, x)
    sc = chart.scales(x)
    Ja = _jacobian(smap, chart, x, F, sc, 1e-7)
    assert smap.analytic_jacobians == 1  # the closed form applied
    smap.analytic = False
    errs = []
    for h in (1e-4, 1e-5):
        Jc = np.empty((x.size, x.size))
        for j in range(x.size):
            d = h * sc[j]
            xp, xm = x.copy(), x.copy()
            xp[j] += d
            xm[j] -= d
            Jc[:, j] = (smap.residual(chart, xp)[0] + xp - smap.residual(chart, xm)[0] - xm) / (2 * d)
        errs.append(np.abs(Jc - Ja).max() / np.abs(Ja).max())
    # central differences converge to it as h^2 (measured 1.9e-7 and 1.9e-9 at h = 1e-4, 1e-5 (SISO),
    # 3e-9 and 2e-9 at h = 1e-5 with 2 inputs and 3 outputs, 1 input and 3 outputs: directions among the
    # coordinates)
    assert errs[1] < 1e-7
    assert errs[1] < errs[0] / 20
    # forward differences (the fallback) agree to their own O(h) accuracy
    Jf = _jacobian(smap, chart, x, F, sc, 1e-7)
    assert np.abs(Jf - Ja).max() < 1e-4 * np.abs(Ja).max()


def test_newton_with_the_closed_form_reaches_a_hermite_interpolant():
    rom_s, sur = _surrogate()
    smap = SurrogateMap(sur, (0.1, 10.0))
    run = iterate(smap, *_point(smap), maxit=15, tol=1e-12, plain=100)
    assert not run["converged"]  # Newton has work left
    res = newton_fixed_point(smap, *run["last"], tol=1e-11)
    assert res.converged and smap.analytic_jacobians >= res.steps
    rom = sur.interpolant(*res.data)
    lam, X = sla.eig(rom.A, rom.E)
    assert np.all(lam.real < 0)
    # H2 optimality: T_r interpolates T_s and its derivative at every mirrored pole (dense transfer functions)
    for s in -lam:
        d_full = rom_s.transfer_derivative(s)[0, 0]
        assert abs(rom_s.transfer(s)[0, 0] - rom.transfer(s)[0, 0]) <= 1e-7 * abs(rom_s.transfer(s)[0, 0])
        assert abs(d_full - rom.transfer_derivative(s)[0, 0]) <= 1e-6 * abs(d_full)
