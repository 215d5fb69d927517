"""Reduced models and the dense kernels: checked against numpy, scipy and python-control."""

from __future__ import annotations

import control
import numpy as np
import pytest

import morsuite as ms
from morsuite.linalg.dense import dense_bt, orth, shift_distance, UnstableError
from morsuite.rom import FirstOrderROM, SecondOrderROM, load_rom
from support import assert_rounding, assert_sets_close, orthonormality_error, transfer_tolerance


def _random_so(r=5, m=2, p=3, seed=0):
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((r, r))
    M = X @ X.T + r * np.eye(r)
    Y = rng.standard_normal((r, r))
    K = Y @ Y.T + r * np.eye(r)
    D = 0.1 * M + 0.05 * K
    return SecondOrderROM(M, D, K, rng.standard_normal((r, m)), rng.standard_normal((p, r)))


def test_second_order_transfer_matches_dense_and_control():
    rom = _random_so()
    s = 0.3 + 1.1j
    P = s * s * rom.M + s * rom.D + rom.K
    ref = rom.L @ np.linalg.solve(P, rom.F)
    # measured 0, bound 2e-14
    assert_rounding(np.linalg.norm(rom.transfer(s) - ref) / np.linalg.norm(ref), transfer_tolerance(P, rom.F, rom.L),
                    "transfer")
    sys_ = rom.to_control()
    omega = np.logspace(-1, 1, 25)
    H = rom.freqresp(omega)
    Hc = np.stack([np.atleast_2d(sys_(1j * w)) for w in omega])
    assert np.max(np.abs(H - Hc)) <= 1e-10 * np.max(np.abs(H))
    fo = rom.to_first_order()
    # two solves per frequency, with the first-order pencil and the second-order one: measured at most
    # 0.012 of the bound (1.4e-14 against 1.2e-12 at w = 8.3, where the velocities are 8 times the positions)
    Hf = fo.freqresp(omega)
    for k, w in enumerate(omega):
        tol = (transfer_tolerance(1j * w * fo.E - fo.A, fo.B, fo.C)
               + transfer_tolerance(-w * w * rom.M + 1j * w * rom.D + rom.K, rom.F, rom.L))
        assert_rounding(np.linalg.norm(Hf[k] - H[k]) / np.linalg.norm(H[k]), tol, f"first-order realization at {w}")
    assert fo.states == rom.states == 2 * rom.order


def test_poles_and_stability():
    rom = _random_so()
    lam = rom.poles()
    assert lam.size == 2 * rom.order
    for x in lam[:3]:
        assert abs(np.linalg.det(x * x * rom.M + x * rom.D + rom.K)) < 1e-8 * np.linalg.norm(rom.K) ** rom.order
    assert rom.is_stable()
    unstable = SecondOrderROM(rom.M, -rom.D, rom.K, rom.F, rom.L)
    assert not unstable.is_stable()


def test_transfer_derivative_matches_finite_difference():
    rom = _random_so()
    s, h = 0.2 + 0.7j, 1e-6
    fd = (rom.transfer(s + h) - rom.transfer(s - h)) / (2 * h)
    assert np.allclose(rom.transfer_derivative(s), fd, rtol=1e-6)


@pytest.mark.parametrize("suffix", [".npz", ".mat"])
def test_save_load_round_trip(tmp_path, suffix):
    rom = _random_so()
    path = rom.save(tmp_path / f"rom{suffix}")
    back = load_rom(path)
    assert isinstance(back, SecondOrderROM)
    for k in ("M", "D", "K", "F", "L"):
        assert np.array_equal(getattr(rom, k), getattr(back, k))
    fo = rom.to_first_order()
    back = load_rom(fo.save(tmp_path / f"fo{suffix}"))
    assert isinstance(back, FirstOrderROM) and np.array_equal(back.A, fo.A)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_rom_bad_input():
    rom = _random_so()
    with pytest.raises(ms.ShapeError, match="matrix D"):
        SecondOrderROM(rom.M, rom.D[:2], rom.K, rom.F, rom.L)
    with pytest.raises(ms.InputError, match="matrix K"):
        SecondOrderROM(rom.M, rom.D, rom.K * np.nan, rom.F, rom.L)
    with pytest.raises(ms.ShapeError, match="matrix B"):
        FirstOrderROM(None, np.eye(3), np.ones((2, 1)), np.ones((1, 3)))
    with pytest.raises(ms.FileFormatError):
        load_rom("/nonexistent/rom.npz")


def test_dense_bt_matches_control_balred():
    rom = _random_so(r=6, m=1, p=1, seed=4)
    E, A, B, C = rom.first_order()
    k = 5
    bt = dense_bt(E, A, B, C, order=k)
    sys_ = control.ss(np.linalg.solve(E, A), np.linalg.solve(E, B), C, np.zeros((1, 1)))
    red = control.balred(sys_, k, method="truncate")
    omega = np.logspace(-2, 2, 40)
    ours = np.array([(bt.C @ np.linalg.solve(1j * w * np.eye(k) - bt.A, bt.B))[0, 0] for w in omega])
    theirs = np.array([red(1j * w) for w in omega]).ravel()
    assert np.max(np.abs(ours - theirs)) <= 1e-8 * np.max(np.abs(theirs))
    hsv_ref = control.hankel_singular_values(sys_)
    assert_sets_close(bt.hsv, hsv_ref, rtol=1e-8, what="HSVs")  # two of them 8e-4 apart; rounding 1e-13
    # the a-priori bound holds
    full = np.array([(C @ np.linalg.solve(1j * w * E - A, B))[0, 0] for w in omega])
    assert np.max(np.abs(full - ours)) <= bt.bound() * (1 + 1e-8)


def test_dense_bt_refuses_unstable():
    rom = _random_so()
    E, A, B, C = SecondOrderROM(rom.M, -rom.D, rom.K, rom.F, rom.L).first_order()
    with pytest.raises(UnstableError):
        dense_bt(E, A, B, C, order=2)


def test_orth_and_shift_distance():
    rng = np.random.default_rng(1)
    X = rng.standard_normal((50, 4))
    X = np.hstack([X, X[:, :1] * 3 + 1e-15])  # a dependent column
    Q, s = orth(X, 1e-12)
    err, tol = orthonormality_error(Q)
    assert Q.shape[1] == 4 and err <= tol, (err, tol)
    a = np.array([1 + 1j, 1 - 1j, 2.0])
    assert shift_distance(a, a[::-1]) == 0.0
    assert shift_distance(a, a[:2]) >= 1.0
