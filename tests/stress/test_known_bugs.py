"""Minimal reproducers of the bugs the stress suite found in code it does not own.

Each test states what must hold; they were marked ``xfail(strict=True)`` until the
bug is fixed: a fix makes it XPASS, which fails the run, so the mark (and the
entry in ``morsuite.stress.KNOWN_BUGS``) gets removed together with the bug.
The models come from ``ms.models.random_constrained`` with fixed seeds.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import morsuite as ms
from morsuite import stress as S
from support import assert_sets_close, eig_tolerance

pytestmark = pytest.mark.stress


def _reduce_is_documented(method, fom, r, **options):
    """Run a reducer: it must return a finite ROM or raise a MorsuiteError (anything else propagates)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            res = ms.reducers.make(method, fom, **options).reduce(r)
        except ms.MorsuiteError:
            return None
    omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), 20)
    assert np.all(np.isfinite(res.rom.freqresp(omega)))
    return res


# -- K1: the saddle-point solve is not equilibrated -----------------------------------
#: 12 masses in grams on springs in kN/mm spread over 12 decades, two constraints; at the top of
#: its default band S(s) has entries from 1 (G) to 1e23 (s^2 M) while its equilibrated condition
#: number is 40 and the null-space pencil N^T P N is perfectly conditioned (cond 1.0)
K1_MODEL = dict(n1=12, n2=2, m=1, p=1, seed=51, stiffness_spread=12.0, mass_unit=1e-6, stiffness_unit=1e9)
K1_OMEGA = 397153169344686.0
#: T(j K1_OMEGA) in exact rational arithmetic (test_k1_references_match_exact_arithmetic)
K1_EXACT = 3.1581028114817277e-24 + 1.4092574334587523e-27j


def test_k1_saddle_solve_accuracy_on_spread_stiffness():
    fom = ms.models.random_constrained(**K1_MODEL)
    assert fom.band[0] < K1_OMEGA <= fom.band[1] * (1 + 1e-12)
    assert S.equilibrated_condition(fom, 1j * K1_OMEGA) < 1e3
    T = fom.transfer(1j * K1_OMEGA)[0, 0]  # measured: -1.45e-23 + 2.1e-24j
    assert abs(T - K1_EXACT) <= 1e-8 * abs(K1_EXACT)


def test_k1_equilibration_restores_the_accuracy():
    """The proposed fix, prototyped by morsuite.stress.equilibrated_saddle, meets the K1 test (passes now)."""
    with S.equilibrated_saddle():
        fom = ms.models.random_constrained(**K1_MODEL)
        T = fom.transfer(1j * K1_OMEGA)[0, 0]
    assert abs(T - K1_EXACT) <= 1e-12 * abs(K1_EXACT)


def test_k1_references_match_exact_arithmetic():
    """Both references of the stress checks (dense null space, equilibrated sparse LU) and the
    stored exact value: T(j w) from rational Gaussian elimination of the real 2N x 2N form."""
    from fractions import Fraction as Fr

    fom = ms.models.random_constrained(**K1_MODEL)
    n1, N = fom.n1, fom.n1 + fom.n2
    M, D, K, G = (X.toarray() for X in (fom.M, fom.D, fom.K, fom.G))
    w = Fr(K1_OMEGA)
    A = [[Fr(0)] * (2 * N + 1) for _ in range(2 * N)]
    for i in range(N):
        for j in range(N):
            if i < n1 and j < n1:
                re, im = Fr(K[i, j]) - w * w * Fr(M[i, j]), w * Fr(D[i, j])
            else:
                re, im = (Fr(G[j - n1, i]) if i < n1 <= j else Fr(G[i - n1, j]) if j < n1 <= i else Fr(0)), Fr(0)
            A[i][j], A[i][j + N], A[i + N][j], A[i + N][j + N] = re, -im, im, re
    for i in range(n1):
        A[i][2 * N] = Fr(fom.F[i, 0])
    n = 2 * N
    for c in range(n):
        p = next(r for r in range(c, n) if A[r][c] != 0)
        A[c], A[p] = A[p], A[c]
        for r in range(n):
            if r != c and A[r][c] != 0:
                f = A[r][c] / A[c][c]
                A[r] = [x - f * y for x, y in zip(A[r], A[c])]
    x = [A[i][n] / A[i][i] for i in range(n)]
    exact = complex(float(sum(Fr(fom.L[0, i]) * x[i] for i in range(n1))),
                    float(sum(Fr(fom.L[0, i]) * x[i + N] for i in range(n1))))
    assert abs(exact - K1_EXACT) <= 1e-15 * abs(K1_EXACT)
    s = 1j * K1_OMEGA
    assert abs(S.nullspace_transfer(fom, s)[0][0, 0] - exact) <= 1e-12 * abs(exact)
    assert abs(S.reference_transfer(fom, s)[0][0, 0] - exact) <= 1e-12 * abs(exact)


# -- K2: IRKA shift update with zero shifts ----------------------------------------------
def test_k2_empty_shift_set():
    fom = ms.models.random_constrained(n1=25, n2=2, m=2, p=3, seed=1164141368, zeta=5.603297000619758e-05,
                                       damping="dashpots", constraints="ties", io="dense",
                                       mass_unit=1e-6, stiffness_unit=1e9)
    _reduce_is_documented("irka", fom, 3, maxit=40)


#: n1 = 12: the input acts on a chain end whose only neighbour is a fixed coordinate, and the
#: outputs read that coordinate and masses beyond it, so T(s) = 0 exactly (a legitimate model)
ZERO_T = dict(n1=12, n2=1, m=1, p=1, zeta=1.0, mass_spread=3.0, constraints="fixes")


def test_k2_empty_shift_set_zero_transfer():
    fom = ms.models.random_constrained(seed=0, **ZERO_T)
    # exact with SuperLU's sparse elimination; the banded LU's Schur complement of the
    # constraint leaves rounding (7e-18 here), and IRKA must be documented on both
    fom.lu_backend = "superlu"
    assert np.abs(fom.transfer(1j)).max() == 0.0
    for backend in ("superlu", "banded"):
        fom.lu_backend = backend
        _reduce_is_documented("irka", fom, 3)


# -- K3: a projection basis of numerical rank 0 ------------------------------------------
def test_k3_zero_input_matrix():
    fom = ms.models.dsms(50).with_io(F=np.zeros((50, 1)))
    _reduce_is_documented("irka", fom, 2)


def test_k3_zero_input_matrix_projected():
    fom = ms.models.dsms(50).with_io(F=np.zeros((50, 1)))
    _reduce_is_documented("irka-projected", fom, 2)


def test_k3_zero_transfer():
    _reduce_is_documented("irka", ms.models.random_constrained(seed=12946, **ZERO_T), 2)


# -- K4: a ROM of order 0 ----------------------------------------------------------------
def test_k4_order_zero_rom_zero_transfer():
    _reduce_is_documented("irka", ms.models.random_constrained(seed=0, **ZERO_T), 2)


def test_k4_order_zero_rom():
    fom = ms.models.random_constrained(n1=30, n2=13, m=2, p=2, seed=1806557838, zeta=1.2815211322768356e-05,
                                       damping="dashpots", mass="consistent", mass_spread=6.0,
                                       stiffness_spread=12.0, constraints="fixes", io="points")
    _reduce_is_documented("irka-projected", fom, 1, maxit=40)


# -- K5: a zero shift from the update ----------------------------------------------------
def test_k5_zero_shift_from_update():
    fom = ms.models.random_constrained(n1=22, n2=5, m=2, p=3, seed=78513031, zeta=0.000759657241381712,
                                       mass_spread=3.0, stiffness_spread=12.0, constraints="general",
                                       io="points", mass_unit=1e-6, stiffness_unit=1e9)
    _reduce_is_documented("irka", fom, 3, maxit=40)


# -- K6: QZ on a badly scaled reduced pencil -----------------------------------------------
#: a 3 x 3 reduced model that IRKA produced on random_constrained(n1=43, mass_unit=1e-6,
#: stiffness_unit=1e9, ...): M ~ 1e-7, D ~ 1e-4, K ~ 1e9; its poles are about -300 +- 5e7 j
K6_M = np.array([
    [9.320924852890525e-07, 2.6068714732058387e-08, -4.470166305201687e-09],
    [2.4879374550268685e-08, 4.7024851788171173e-07, -1.4269973005718522e-09],
    [-2.4420888179852016e-08, 2.5164638747356234e-09, 3.237517392466862e-07]])
K6_D = np.array([
    [0.0005225009702871128, 1.140195854215521e-05, -3.0473508335200084e-06],
    [1.2540115994758173e-05, 0.00025641101656277704, -3.405305035077171e-05],
    [-2.044280178048981e-06, -3.9672671377651846e-05, 0.0002051900711030441]])
K6_K = np.array([
    [2331027865.7402, 43763605.19269554, -14793019.622906342],
    [52833827.81286755, 1128007179.8557339, -225480383.5714241],
    [16640631.154862018, -267872472.15072936, 967851163.940426]])


def test_k6_rom_poles_badly_scaled():
    rom = ms.rom.SecondOrderROM(K6_M, K6_D, K6_K, np.ones(3), np.ones(3))
    lam = rom.poles()
    assert lam.size == 6 and np.all(lam.real < 0)


def test_k6_scaling_the_pencil_gives_the_poles():
    """The proposed fix: lambda = g mu with g = sqrt(|K| / |M|); mu solves det(mu^2 g^2 M + mu g D + K) = 0.

    Reference: the standard form E^-1 A (M is well conditioned) by geev, accurate to the bound
    from its balanced eigenvalue condition numbers (about 1e-7 here). The scaled pencil is
    accurate to its own first-order bound eps kappa (|A| + |mu| |E|) g: 35 to 46 for poles of
    modulus 5e7 with real parts near -300 (measured 0.07 to 4.3 off); the test allows
    eig_tolerance's factor 10 on it. Matched, not sorted: QZ returns the two members of a pair
    with real parts that differ in the last bits, so their sorted order depends on the BLAS."""
    g = np.sqrt(np.linalg.norm(K6_K) / np.linalg.norm(K6_M))
    I, Z = np.eye(3), np.zeros((3, 3))
    mu, tol = eig_tolerance(np.block([[Z, I], [-K6_K, -K6_D * g]]), np.block([[I, Z], [Z, K6_M * g ** 2]]))
    lam = mu * g
    assert np.all(np.isfinite(lam)) and np.all(lam.real < 0)
    A = np.block([[Z, I], [-np.linalg.solve(K6_M, K6_K), -np.linalg.solve(K6_M, K6_D)]])
    tol_ref = eig_tolerance(A, balance=True)[1]  # geev balances A first
    ref = np.linalg.eigvals(A)
    assert np.all(np.abs(ref.imag) > 1e7) and np.all(tol_ref < 1e-5)
    assert_sets_close(lam, ref, atol=np.max(tol * g) + np.max(tol_ref), what="poles of the scaled pencil")


# -- K7: LR-ADI with no usable shift --------------------------------------------------------
#: found by the 2000-case run: masses in grams and stiffnesses in kN/mm, both spread over many
#: decades; the projected pencil of the first ADI block has no finite stable Ritz value, and
#: lradi popped from an empty shift queue (IndexError) or took max() of an empty score array
K7_MODEL = dict(n1=38, n2=5, m=3, p=3, seed=544491153, zeta=0.00789689195080825, damping="rayleigh",
                mass="consistent", mass_spread=3.0, stiffness_spread=12.0, constraints="ties", io="points",
                mass_unit=1e-6, stiffness_unit=1e9)


def test_k7_lradi_without_usable_shift_is_a_documented_error(monkeypatch):
    """With QZ on the projected pencil (STANDARD_RCOND = 0) the first block has no finite stable
    Ritz value: a documented ModelError, never an IndexError."""
    from morsuite.linalg import adi_shifts

    monkeypatch.setattr(adi_shifts, "STANDARD_RCOND", 0.0)
    fom = ms.models.random_constrained(**K7_MODEL)
    with pytest.raises(ms.ModelError, match="no usable shift"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ms.reducers.make("bt", fom, maxiter=150).reduce(12)


def test_k7_fixed_by_standard_form_ritz_values():
    """The default computes the Ritz values from E^-1 A when X^T M X is well conditioned (it is
    here): ADI converges and the BT error bound holds against the full model's response."""
    fom = ms.models.random_constrained(**K7_MODEL)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = ms.reducers.make("bt", fom, maxiter=150).reduce(12)
    adi = res.info["adi"]
    assert adi["controllability"]["converged"] and adi["observability"]["converged"]
    omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), 40)
    err = ms.analysis.errors(fom, res.rom, omega).abs_error.max()
    assert 0 < err <= res.info["error_bound"]  # measured 1.7e-18 against 1.0e-14
