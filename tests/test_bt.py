"""Balanced truncation ("bt"): reference Hankel singular values and errors, a dense check,
the second-order balancing levels, Gramian reuse, options, and the command line.

The expensive objects (the DSMS g = 6000 and TCOM nc = 2000 reducers with their
Gramians, the DSMS frequency response) are module-scoped and shared by the tests.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.reducers.bt.balanced import FORMS
from support import assert_sets_close

DSMS_HSV = np.array([0.1326606742, 0.08189541682, 0.02236780891, 0.01676544437, 2.494449919e-3,
                     1.314023856e-3, 1.900404101e-4, 9.130129237e-5, 1.1734114e-5, 7.451744415e-6])
TCOM_HSV = np.array([8.8123724e7, 1.6155685e7, 7.4640087e6, 3.3452446e5, 2.8928455e5, 1.0357658e5,
                     94600.253, 62837.965, 59429.09, 24243.81])
LEVELS = ("pp", "pv", "vp", "vv", "fv")


@pytest.fixture(scope="module")
def dsms6000():
    return ms.models.dsms(g=6000)


@pytest.fixture(scope="module")
def dsms_grid(dsms6000):
    omega = ms.analysis.freq_grid((1e-2, 1.0), 200)
    return omega, dsms6000.freqresp(omega)


@pytest.fixture(scope="module")
def dsms_bt(dsms6000):
    red = ms.reducers.make("bt", dsms6000)
    red.reduce(10)  # Gramians
    return red


@pytest.fixture(scope="module")
def tcom_bt(tcom2000):
    red = ms.reducers.make("bt", tcom2000)
    red.reduce(10)
    return red


def max_error(fom, rom, grid):
    omega, H = grid
    return float(ms.analysis.errors(fom, rom, omega, H_full=H).abs_error.max())


# -- DSMS: the reference of models.md --------------------------------------------
def test_dsms_hankel_singular_values(dsms_bt):
    info = dsms_bt.reduce(10).info
    hsv = np.asarray(info["hsv"])
    assert_sets_close(hsv[:10], DSMS_HSV, rtol=1e-6, what="HSVs")
    assert info["converged"] and info["adi_iterations"]["controllability"] <= 40
    assert info["adi_iterations"]["observability"] <= 40


def test_dsms_first_order_errors_and_bound(dsms6000, dsms_grid, dsms_bt):
    res = dsms_bt.reduce(10)
    err = max_error(dsms6000, res.rom, dsms_grid)
    assert res.info["kind"] == "first-order" and res.info["r"] == res.info["states"] == 10
    assert res.info["stable"] and err <= 1.3e-6 and err <= res.info["error_bound"]
    # r = 20 is at 1e-11 of the largest HSV: lradi's tolerance 1e-10 leaves the tail HSVs (and the
    # bound) 10-20% low (2.2e-12 against a computed bound of 2.0e-12); bt's default 1e-12 resolves them
    res20 = dsms_bt.reduce(20)
    err20 = max_error(dsms6000, res20.rom, dsms_grid)
    assert res20.info["options"]["tol"] == 1e-12
    assert res20.info["r"] == 20 and err20 <= 2e-12 and err20 <= res20.info["error_bound"]
    # the documented case: one fresh LU per projection shift (the shift sequence it was seen with)
    coarse = ms.reducers.make("bt", dsms6000, tol=1e-10, shift_reuse=0.0, lu_pool_mib=0.0).reduce(20)
    assert coarse.info["error_bound"] < err20 * 1.2  # the coarse bound is the one that fails


def test_dsms600_hsv_against_dense_modal_computation():
    r"""Dense reference on the projected model: orthonormal null-space basis of G, the modal
    decomposition of the projected (M, K) (the DSMS damping D = 2.5 K is proportional, so the
    model decouples into 2 x 2 blocks), both Gramians from 2 x 2 Sylvester equations per pair of
    modes, Hankel singular values by the square-root method.

    Agreement to 1e-8 relative holds for the singular values above 1e-5 of the largest; below,
    both computations lose relative accuracy (a backward-stable SVD is exact to about
    eps * sigma_1 absolutely, i.e. 2e-7 relative at 1e-9 * sigma_1), so the rest is compared
    absolutely: measured 1.1e-13 to 1.9e-13 times sigma_1 over eight BLAS kernel / thread /
    SIMD settings (rounding of the dense reference), tested at 2e-12 (still 1.5e-3 relative
    at the smallest). The counts are safe: the 18th value is 1.2856e-9 sigma_1 in all of them."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):  # 1198 x 1198 dense work: threads only contend
        dense = _dense_modal_hsv(ms.models.dsms(g=600))
    res = ms.reducers.make("bt", ms.models.dsms(g=600), tol=1e-14).reduce(10)
    hsv = np.asarray(res.info["hsv"])
    n_big = int(np.sum(dense > 1e-5 * dense[0]))
    n_mid = int(np.sum(dense > 1e-9 * dense[0]))
    assert n_big == 10 and n_mid == 18
    assert_sets_close(hsv[:n_big], dense[:n_big], rtol=1e-8, what="HSVs above 1e-5 sigma_1")
    assert_sets_close(hsv[n_big:n_mid], dense[n_big:n_mid], atol=2e-12 * dense[0], what="HSVs above 1e-9 sigma_1")


def test_automatic_compression_above_its_size_keeps_the_hankel_singular_values(monkeypatch):
    """compress_tol=None: plain factors below BT.COMPRESS_MIN_N1 positions (recorded 0), compressed
    at BT.COMPRESS_AUTO_TOL from there on (the threshold lowered on the instance) once a factor
    exceeds lradi's ``compress_from_mib`` (1024 MiB: these factors stay plain; set to 0 here).
    Compression moves P and Q by at most tol^2 = 1e-12 of their norms, a Hankel singular value
    sigma_i by about 1e-12 sigma_1^2 / sigma_i: the compressed run's values above 1e-5 sigma_1
    match the dense modal reference to 1e-5 relative (measured 5.3e-7), the next ones to 1e-8
    sigma_1 (5.6e-10)."""
    import functools

    from morsuite.linalg import gramians
    fom = ms.models.dsms(g=200)
    dense = _dense_modal_hsv(fom)
    plain = ms.reducers.make("bt", fom, gramian_cache="reducer").reduce(10)
    red = ms.reducers.make("bt", fom, gramian_cache="reducer")
    red.COMPRESS_MIN_N1 = 0
    fits = red.reduce(10)  # compress_tol 1e-6, but the factors fit within compress_from_mib: kept plain
    monkeypatch.setattr(gramians, "lradi_pair", functools.partial(gramians.lradi_pair, compress_from_mib=0.0))
    red = ms.reducers.make("bt", fom, gramian_cache="reducer")
    red.COMPRESS_MIN_N1 = 0
    comp = red.reduce(10)
    assert fom.n1 < ms.reducers.bt.balanced.BT.COMPRESS_MIN_N1 and plain.info["compress_tol"] == 0.0
    assert comp.info["compress_tol"] == fits.info["compress_tol"] == ms.reducers.bt.balanced.BT.COMPRESS_AUTO_TOL
    for eq in ("controllability", "observability"):
        assert plain.info["factor_ranks"][eq] == plain.info["adi"][eq]["columns"]
        assert fits.info["factor_ranks"][eq] == fits.info["adi"][eq]["columns"]
        assert fits.info["adi"][eq]["compressions"] == 0 and fits.info["adi"][eq]["compress_from_mib"] == 1024.0
        assert comp.info["factor_ranks"][eq] < comp.info["adi"][eq]["columns"]
    # the same plain factors, so the same Hankel singular values to rounding
    assert_sets_close(fits.info["hsv"], plain.info["hsv"], atol=1e-13 * plain.info["hsv"][0], what="plain HSVs")
    n_big, n_mid = int(np.sum(dense > 1e-5 * dense[0])), int(np.sum(dense > 1e-9 * dense[0]))
    hsv = np.asarray(comp.info["hsv"])
    assert_sets_close(hsv[:n_big], dense[:n_big], rtol=1e-5, what="HSVs above 1e-5 sigma_1")
    assert_sets_close(hsv[n_big:n_mid], dense[n_big:n_mid], atol=1e-8 * dense[0], what="HSVs above 1e-9 sigma_1")


def _dense_modal_hsv(fom):
    """Hankel singular values of the DSMS on ker G by modal decomposition (see above)."""
    M, D, K, G = (X.toarray() for X in (fom.M, fom.D, fom.K, fom.G))
    Th = sla.null_space(G)
    lam, U = sla.eigh(Th.T @ K @ Th, Th.T @ M @ Th)  # U^T Mq U = I
    d = np.diag(U.T @ (Th.T @ D @ Th) @ U)
    f, l = U.T @ Th.T @ fom.F, fom.L @ Th @ U
    k = lam.size
    A = np.zeros((k, 2, 2))
    A[:, 0, 1], A[:, 1, 0], A[:, 1, 1] = 1.0, -lam, -d
    b = np.zeros((k, 2, 1))
    b[:, 1, :] = f
    c = np.zeros((fom.p, k, 2))
    c[:, :, 0] = l
    I2 = np.eye(2)

    def gram(Ablk, rhs):
        X = np.zeros((2 * k, 2 * k))
        for i in range(k):  # A_i X_ij + X_ij A_j^T = -rhs_ij for all j at once (column-major vec)
            L = np.kron(I2, Ablk[i])[None] + np.einsum("jab,cd->jacbd", Ablk, I2).reshape(k, 4, 4)
            x = np.linalg.solve(L, -rhs[i].transpose(0, 2, 1).reshape(k, 4, 1))[..., 0]
            X[2 * i:2 * i + 2] = x.reshape(k, 2, 2).transpose(0, 2, 1).transpose(1, 0, 2).reshape(2, 2 * k)
        return X

    P = gram(A, np.einsum("iam,jbm->ijab", b, b))
    Q = gram(A.transpose(0, 2, 1), np.einsum("pia,pjb->ijab", c, c))

    def factor(X):
        w, V = np.linalg.eigh(0.5 * (X + X.T))
        return V * np.sqrt(np.clip(w, 0, None))

    return np.linalg.svd(factor(Q).T @ factor(P), compute_uv=False)


# -- TCOM ---------------------------------------------------------------------------
@pytest.mark.slow
def test_tcom_gramians_and_hankel_singular_values(tcom_bt):
    info = tcom_bt.reduce(10).info
    its = info["adi_iterations"]
    hist = info["residual_history"]
    assert info["converged"]
    assert hist["controllability"][-1] <= 1e-12 and hist["observability"][-1] <= 1e-12
    # The issue asked for <= 300 iterations per Gramian. Not attainable by LR-ADI in this residual
    # norm: ADI with the exact eigenvalues as shifts, chosen greedily by residual content, needs
    # 128 / 372 / 606 iterations for nc = 50 / 200 / 500 (dense modal simulation). The default
    # shifts need about 950 for 1e-10 and 1200 for bt's default 1e-12; the independent implementation
    # about 1200 for 1e-10. Guard that level.
    assert its["controllability"] <= 1350 and its["observability"] <= 1350
    assert info["lu_count"] <= 700  # one LU per shift serves both equations
    hsv = np.asarray(info["hsv"])
    assert_sets_close(hsv[:10], TCOM_HSV, rtol=1e-4, what="HSVs")


@pytest.mark.parametrize("model", ["dsms", pytest.param("tcom", marks=pytest.mark.slow)])
def test_second_order_levels_stable_or_say_why(model, request):
    base = request.getfixturevalue(f"{model}_bt")   # only the model's own fixture (the TCOM's costs 7 s)
    for form in LEVELS:
        red = ms.reducers.make("bt", base.fom, form=form).use_gramians_of(base)
        for r in (10, 20, 30):
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                res = red.reduce(r)
            info = res.info
            assert res.rom.kind == "second-order" and info["states"] == 2 * info["r"]
            assert info["lu_count"] == 0 and info["setup_reused"]
            assert info["stable"] == res.rom.is_stable()
            if not info["stable"]:  # says so: a warning, recorded in info, with the count
                assert any(issubclass(w.category, ms.StabilityWarning) for w in caught)
                assert any("StabilityWarning" in w and form in w for w in info["warnings"])
                assert info["unstable_poles"] > 0
            if info["r"] < r:  # capped: says so
                assert any("RankWarning" in w for w in info["warnings"])
            if form == "fv":  # a congruence of symmetric positive definite data: always stable
                assert info["stable"]
    # on these models every level is stable except vp on the TCOM (r = 20, 30)


# -- reuse, orders, options -------------------------------------------------------
def test_sweep_reuses_gramians(dsms6000):
    red = ms.reducers.make("bt", dsms6000, gramian_cache="reducer")  # the model's cache has dsms_bt's
    first = red.reduce(4)
    assert not first.info["setup_reused"] and first.info["lu_count"] > 0
    infos = [red.reduce(r).info for r in (6, 8, 12)]
    for info in infos:
        assert info["setup_reused"] and info["lu_count"] == 0 and info["time_breakdown"]["adi"] == 0.0
        assert info["hsv"] == first.info["hsv"]
        assert info["setup_cost"]["adi"] == first.info["setup_cost"]["adi"]


def test_orders_and_rank_cap():
    fom = ms.models.dsms(g=600)
    red = ms.reducers.make("bt", fom)
    res = red.reduce(12)
    assert isinstance(res.rom, ms.rom.FirstOrderROM) and res.rom.order == 12 and res.info["states"] == 12
    vv = ms.reducers.make("bt", fom, form="vv").use_gramians_of(red).reduce(12)
    assert isinstance(vv.rom, ms.rom.SecondOrderROM) and vv.info["r"] == 12 and vv.info["states"] == 24
    assert vv.info["error_bound"] is None and len(vv.info["level_singular_values"]) > 0
    with pytest.warns(ms.RankWarning, match="r capped from 60"):
        capped = red.reduce(60)
    assert capped.info["r"] < capped.info["r_requested"] == 60
    with pytest.raises(ms.InputError, match="first-order states"):
        red.reduce(2 * fom.order + 1)
    with pytest.raises(ms.InputError, match="r must be a positive integer"):
        red.reduce(0)


def test_options_validated():
    fom = ms.models.dsms(g=50)
    with pytest.raises(ms.OptionError, match="unknown option.*'level'.*valid options: compress_tol, form"):
        ms.reducers.make("bt", fom, level="vv")
    with pytest.raises(ms.OptionError, match="'form' parameter of BT"):
        ms.reducers.make("bt", fom, form="velocity")
    with pytest.raises(ms.OptionError, match="'tol' parameter"):
        ms.reducers.make("bt", fom, tol=0.0)
    a = ms.reducers.make("bt", fom)
    with pytest.raises(ms.OptionError, match="different ADI options \\(tol\\)"):
        ms.reducers.make("bt", fom, tol=1e-8).use_gramians_of(a)
    with pytest.raises(ms.InputError, match="different model"):
        ms.reducers.make("bt", ms.models.dsms(g=50)).use_gramians_of(a)
    assert set(FORMS) == {"first-order", "pp", "pv", "vp", "vv", "fv"}
    info = a.reduce(4).info
    assert info["options"]["form"] == "first-order" and info["options"]["tol"] == 1e-12


def test_unconverged_adi_warns_and_says_so():
    fom = ms.models.dsms(g=200)
    with pytest.warns(ms.ConvergenceWarning, match="maxiter = 4"):
        res = ms.reducers.make("bt", fom, maxiter=4).reduce(4)
    assert res.info["converged"] is False
    assert any("ConvergenceWarning" in w for w in res.info["warnings"])


def test_cli_reduce_json(capsys):
    from morsuite.cli import main

    # the reduction's record only: the norms of `reduce --json` are tested on dsms:g=40
    # (test_studies_norms_time.py); here they would add the Hinf certificate of 599 hidden positions
    assert main(["reduce", "--model", "dsms:g=600", "--method", "bt", "--r", "10", "--json", "--no-norms"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["method"] == "bt" and out["r"] == 10 and out["converged"] and out["stable"]
    assert out["max_abs_error"] < 2e-6 and out["lu_count"] > 0
