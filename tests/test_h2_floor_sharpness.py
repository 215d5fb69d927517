"""How sharp the error-Gramian route's floor is (issue 25): floor / actual error, against a reference that
resolves the actual error.

Reference: the same LR-ADI recurrence, with the model's own shifts, run in long double on both sides of the
error system, independently of morsuite's recurrence: the model through its dense hidden-manifold
realization (explicit null(G) basis, tests/test_norms.py ``hidden_ss``) and the reduced model through its
(E, A, B, C), each step a double LU of (A + pE) refined three times with the residual in long double (about
1e-19 relative here), the residual factor updated in long double. The output columns ``LZ_p`` and ``C_rZ_r``
are invariant under the change of realization, so ``||LZ - C_rZ_r||_F^2`` in long double plus the evaluator's
own tail terms (t1 - 2 t2 + t3, shared) is the value with the columns' rounding removed; the columns' rounding
is what the floor's dominant term bounds (docs/design/norms.md, "Sharpness of the floor", 2026-11-26). The tail
terms' own errors are checked against independent references in tests/test_h2_certified.py.

Measured (2026-11-26, OpenBLAS, one thread): floor / error from 34 to 190,000, median 560 over these
eleven reduced models (dsms(60), BT at 12 states, error 5e-21 against a floor of 9e-16, is the extreme);
every floor above its error. Issue 25's "at most 10x pessimistic at the median" is NOT
met: the floor bounds the inner product of the columns' difference with their rounding by Cauchy-Schwarz, and
the rounding is nearly orthogonal to the difference (docs/design/norms.md). The bound below (5,000, about ten
times the measured median) guards against the floor getting looser; it is not the issue's target.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.linalg.gramians import cached_gramian_factors
from support import assert_rounding, rounding_unit
from test_norms import hidden_ss

LD, CLD = np.longdouble, np.clongdouble


def _solve_ld(M, Mld, b, steps=3):
    lu = sla.lu_factor(M)
    x = sla.lu_solve(lu, np.asarray(b, dtype=complex)).astype(CLD)
    for _ in range(steps):
        x = x + sla.lu_solve(lu, np.asarray(b - Mld @ x, dtype=complex)).astype(CLD)
    return x


def ld_adi_columns(shifts, E, A, B, C):
    """C Z of LR-ADI on (E, A, B, C) with the given shifts, entirely in long double (generalized form: real
    shift p: columns sqrt(-2p) C V, W += -2p E V; complex pair: g C R, c C Im V, W += g^2 E R with
    V = (A + pE)^{-1} W, R = Re V + (Re p / Im p) Im V, g = 2 sqrt(-Re p), c = g sqrt(1 + (Re p/Im p)^2))."""
    El, Al, Cl = (np.asarray(X, dtype=LD) for X in (E, A, C))
    W = np.asarray(B, dtype=LD)
    sh = np.asarray(shifts, dtype=complex)
    cols, i = [], 0
    while i < sh.size:
        p = sh[i]
        V = _solve_ld(A + p * E, Al + CLD(p) * El, W)
        if p.imag != 0:
            g = 2 * np.sqrt(-LD(p.real))
            d = LD(p.real) / LD(p.imag)
            R = V.real + d * V.imag
            cols += [g * (Cl @ R), (g * np.sqrt(d * d + 1)) * (Cl @ V.imag)]
            W = W + (g * g) * (El @ R)
            i += 2
        else:
            w = -2 * LD(p.real)
            cols.append(np.sqrt(w) * (Cl @ V.real))
            W = W + w * (El @ V.real)
            i += 1
    return np.hstack(cols)


CASES = [("tcom:nc=20", [("bt", 4), ("bt", 8), ("bt", 12), ("bt", 20), ("bt", 30), ("irka", 6), ("bt", 40)]),
         ("dsms:g=60", [("bt", 4), ("bt", 8), ("bt", 12), ("irka", 6)])]


def test_error_gramian_floor_bounds_its_error_and_its_pessimism_is_measured():
    ratios = []
    for spec, roms in CASES:
        fom = ms.models.parse(spec)
        ms.analysis.h2_norm(fom)
        shifts = cached_gramian_factors(fom).controllability.shifts
        A, B, C = hidden_ss(fom)
        LZ = ld_adi_columns(shifts, np.eye(A.shape[0]), A, B, C)
        for method, r in roms:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                rom = ms.reducers.make(method, fom).reduce(r).rom
                # rtol 1e-14: the tail cross term t2 is computed, so the columns' rounding is the floor's main term
                value, d = ms.analysis.h2_error(fom, rom, method="error-gramian", rtol=1e-14, details=True)
            rec = d["error_gramian"]
            assert rec["t2"] is not None
            Er, Ar, Br, Cr = rom.first_order() if rom.kind == "second-order" else (rom.E, rom.A, rom.B, rom.C)
            diff = LZ - ld_adi_columns(shifts, Er, Ar, Br, Cr)
            ref = float(np.sqrt(float(np.sum(diff * diff)) + rec["squared"] - rec["columns"]))
            err = abs(value - ref)
            assert err <= d["floor"], (spec, method, r, err, d["floor"])
            ratios.append(d["floor"] / max(err, 1e-300))
    assert min(ratios) >= 1.0
    assert np.median(ratios) <= 5000.0, sorted(ratios)


@pytest.mark.parametrize("coupling", [0.0, 300.0], ids=["eigenbasis", "schur"])
def test_reduced_recurrence_against_long_double(coupling):
    """rom_adi's columns and residual against the long-double recurrence: in closed form in the eigenbasis
    (well-conditioned X) and through the Schur form (coupling 300 makes kappa(X) about 1e4 > KAPPA_MODAL)."""
    from morsuite.norms.error_gramian import KAPPA_MODAL, rom_adi

    fom = ms.models.tcom(nc=20)
    ms.analysis.h2_norm(fom)
    shifts = cached_gramian_factors(fom).controllability.shifts
    rng = np.random.default_rng(3)
    lam = np.array([-0.02 + 1.3j, -0.05 + 0.4j, -0.3 + 2.0j])
    n = 2 * lam.size
    A = np.zeros((n, n))
    for i, z in enumerate(lam):
        A[2 * i:2 * i + 2, 2 * i:2 * i + 2] = [[z.real, z.imag], [-z.imag, z.real]]
    A[0:2, 2:4] = coupling * np.eye(2)  # non-normal coupling of two nearby modes
    E = np.eye(n) + 0.1 * np.diag(rng.random(n))
    A = E @ A
    B, C = rng.standard_normal((n, 1)), rng.standard_normal((1, n))
    X = np.linalg.eig(np.linalg.solve(E, A))[1]
    kappa = np.linalg.cond(X / np.linalg.norm(X, axis=0))
    assert (kappa <= KAPPA_MODAL) == (coupling == 0.0)
    run = rom_adi(shifts, E, A, B, C)
    ref = ld_adi_columns(shifts, E, A, B, C).astype(float)
    assert run.CZ.shape == ref.shape
    # each of the recurrence's steps adds a solve's rounding (in the eigenbasis: times kappa(X); the Schur
    # form is unitary): measured 1.4e-15, 2.2e-15 on one machine, 3.4e-15, 6.5e-15 on another, bound 2.4e-12
    steps_unit = len(shifts) * rounding_unit(n) * (kappa if kappa <= KAPPA_MODAL else 1.0)
    assert_rounding(np.linalg.norm(run.CZ - ref) / np.linalg.norm(ref), steps_unit, "columns against long double")
