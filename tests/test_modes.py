"""linalg.eigen and analysis.modes against dense references: constrained undamped modes (null space
of G), damped poles (QZ of the dense first-order realization), MAC, matching, structure checks."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.errors import InputError, ShapeError
from morsuite.linalg.eigen import constrained_modes
from morsuite.linalg.poles import damped_poles
from support import assert_rounding, assert_sets_close, dense_modes, eig_tolerance, orthonormality_error, rounding_unit


@pytest.fixture(scope="module")
def block():
    return ms.models.fem_block(400)  # Rayleigh damping: the damped shapes are the undamped ones


@pytest.fixture(scope="module")
def tcom():
    return ms.models.tcom(nc=40)


def dense_poles(fom):
    """Finite eigenvalues (Im >= 0) of the dense first-order realization (E, A) of size 2 n1 + n2."""
    E, A, _, _ = fom.first_order()
    lam = sla.eigvals(A.toarray(), E.toarray())
    lam = lam[np.isfinite(lam)]
    return lam[lam.imag >= 0]


@pytest.mark.parametrize("name", ["dsms", "tcom", "block"])
def test_constrained_modes_against_the_null_space_reference(name, block, tcom):
    fom = {"dsms": ms.models.dsms(g=100), "tcom": tcom, "block": block}[name]
    w_ref, _ = dense_modes(fom)
    res = constrained_modes(fom, k=12)
    assert_sets_close(res.omega, w_ref[:12], rtol=1e-10, what="lowest constrained modes")
    Phi = res.shapes
    err, tol = orthonormality_error(Phi, fom.M)
    assert err <= tol, (err, tol)
    # constraint rows of backward-stable solves, relative to ||G||_inf max|Phi| (as for the ADI factors);
    # measured <= 4e-16, bound >= 2e-13
    assert_rounding(np.abs(fom.G @ Phi).max() / (abs(fom.G).sum(axis=1).max() * np.abs(Phi).max()),
                    10 * rounding_unit(fom.n1 + fom.n2), "G Phi")
    assert res.residuals.max() < 1e-11 and res.info["lu_count"] == 1
    # every mode of a band, and nothing else
    band = (0.5 * (w_ref[5] + w_ref[6]), 0.5 * (w_ref[20] + w_ref[21]))
    rb = constrained_modes(fom, band=band)
    assert rb.info["covered"] and rb.info["lu_count"] == 1
    assert_sets_close(rb.omega, w_ref[6:21], rtol=1e-10, what="band modes")


def test_constrained_modes_refuses_bad_input(tcom):
    with pytest.raises(InputError, match=r"k = 116 exceeds n1 - n2 - 1 = 114"):
        constrained_modes(tcom, k=116)
    with pytest.raises(InputError, match="band must satisfy 0 <= w1 < w2.*empty"):
        constrained_modes(tcom, band=(2.0, 1.0))
    with pytest.raises(InputError, match="holds no mode"):
        constrained_modes(tcom, band=(1e3, 2e3))
    with pytest.raises(InputError, match="needs k .* or band"):
        constrained_modes(tcom)
    with pytest.raises(InputError, match="k must be a positive integer"):
        constrained_modes(tcom, k=0)


@pytest.mark.parametrize("name, proportional", [("tcom", None), ("block", False), ("dsms", False),
                                                 ("block", None), ("dsms", None)])
def test_damped_poles_against_the_dense_first_order_realization(name, proportional, block, tcom):
    """Both paths (Arnoldi on the first-order pencil; the Rayleigh-damping path from the undamped modes,
    taken by default on the block and the DSMS) against the dense QZ of the first-order realization."""
    fom, band = {"tcom": (tcom, (0.05, 1.0)), "block": (block, (0.5, 3.0)),
                 "dsms": (ms.models.dsms(g=60), (0.1, 0.2))}[name]
    res = damped_poles(fom, band, proportional=proportional)
    assert res.info["method"] == ("proportional" if name != "tcom" and proportional is None else "arnoldi")
    ref = dense_poles(fom)
    f = np.abs(ref)
    inside = ref[(f >= band[0]) & (f <= band[1])]
    got = res.poles[res.in_band]
    # the dense poles in the band, every one found (matched by tolerance: tcom and the block
    # have double poles, each kept once per dimension of its eigenspace)
    assert_sets_close(got, inside, rtol=1e-8, what="damped poles in the band")
    # backward errors of the Ritz pairs (10: the Arnoldi relation over the Krylov vectors): measured <= 2e-15,
    # at most 0.01 of the bound
    assert_rounding(res.residuals.max(), 10 * rounding_unit(fom.n1 + fom.n2), "pole residuals")
    assert res.info["covered"] and res.info["lu_count"] == len(res.info["shifts"])
    assert np.allclose(res.damping, -res.poles.real / np.abs(res.poles))
    with pytest.raises(InputError, match="band must satisfy"):
        damped_poles(fom, (1.0, 1.0))


def _rayleigh_fit_error(fom, a, b, a0, b0):
    """(error, rounding level) of the fitted Rayleigh coefficients: the error in the norm the fit
    minimises, (|a - a0| ||M||_F + |b - b0| ||K||_F) / ||D||_F, and rounding_unit(nnz(D)) times the
    condition number of the fit's scaled 2 x 2 normal equations (which square that of [M, K])."""
    M, K, D = fom.M, fom.K, fom.D
    inner = lambda X, Y: float(X.multiply(Y).sum())
    nM, nK, nD = np.sqrt(inner(M, M)), np.sqrt(inner(K, K)), np.sqrt(inner(D, D))
    c = inner(M, K) / (nM * nK)
    err = (abs(a - a0) * nM + abs(b - b0) * nK) / nD
    return err, rounding_unit(D.nnz) * np.linalg.cond(np.array([[1.0, c], [c, 1.0]]))


def test_proportional_damping_detection(block, tcom):
    """Rayleigh coefficients recovered to rounding where D = alpha M + beta K was assembled (the block:
    0.001, 0.01; the DSMS: D = 2.5 K), None where it is not (the TCOM; the block with one entry of D
    perturbed by 1e-9 of its norm), and proportional=True refused there."""
    for fom, (a0, b0) in ((block, (1e-3, 1e-2)), (ms.models.dsms(g=60), (0.0, 2.5))):
        a, b = ms.linalg.poles.proportional_damping(fom)
        # measured 4e-16 (block) and 2e-15 (DSMS), bounds 1e-12 and 6e-13
        assert_rounding(*_rayleigh_fit_error(fom, a, b, a0, b0), f"Rayleigh coefficients of {fom.name}")
    assert ms.linalg.poles.proportional_damping(tcom) is None
    D = block.D.tolil(copy=True)
    D[3, 3] += 1e-9 * abs(block.D).max()
    bent = ms.models.Index3Model(block.M, D.tocsr(), block.K, block.G, block.F, block.L, band=block.band)
    assert ms.linalg.poles.proportional_damping(bent) is None
    with pytest.raises(InputError, match="proportional=True"):
        damped_poles(tcom, (0.05, 1.0), proportional=True)


def test_model_modes_is_memoised_and_matches_a_modal_rom(block):
    band = (0.5, 3.0)
    full = ms.analysis.model_modes(block, band)
    assert ms.analysis.model_modes(block, band) is full
    rom = ms.reducers.make("modal", block, static_correction=False).reduce(14).rom
    red = ms.analysis.rom_modes(rom, band)
    table = ms.analysis.match_modes(full, red, band)
    matched = table[table.status == "matched"]
    # Rayleigh damping keeps the modal ROM's poles those of the full model
    assert len(matched) == int(full.in_band.sum()) and (table.status == "spurious").sum() == 0
    assert matched.rel_freq_error.max() < 1e-8 and matched.damping_error.abs().max() < 1e-8
    # MAC of the lifted shapes against the full model's: 1 on the simple modes (a double pole's shapes
    # are any basis of its eigenspace: there the full model's shapes lie in the span of the ROM's)
    f = full.frequencies[matched.full_index]
    simple = np.array([np.sum(np.abs(full.frequencies - x) < 1e-6 * x) == 1 for x in f])
    assert simple.sum() >= 4
    A = ms.analysis.mac(full.shapes[:, matched.full_index[simple]], red.shapes[:, matched.rom_index[simple]])
    assert np.abs(np.diag(A) - 1).max() < 1e-8
    double = matched[~simple]
    for x in np.unique(np.round(full.frequencies[double.full_index], 8)):
        i = double.full_index[np.isclose(full.frequencies[double.full_index], x, rtol=1e-6)]
        j = double.rom_index[np.isclose(full.frequencies[double.full_index], x, rtol=1e-6)]
        Q, _ = np.linalg.qr(red.shapes[:, j])
        X = full.shapes[:, i]
        assert np.linalg.norm(X - Q @ (Q.conj().T @ X)) < 1e-8


def test_match_modes_reports_missing_and_spurious(tcom):
    band = (0.05, 1.0)
    full = ms.analysis.model_modes(tcom, band)
    rom = ms.reducers.make("modal", tcom, static_correction=False).reduce(3).rom
    red = ms.analysis.rom_modes(rom, band)
    # a spurious pole: the reduced poles moved by 20 %
    moved = ms.linalg.poles.PolesResult(red.poles * 1.2, red.shapes, red.frequencies * 1.2, red.damping,
                                        red.in_band, red.residuals, red.info)
    t = ms.analysis.match_modes(full, moved, band)
    n_in = int(full.in_band.sum())
    assert (t.status == "missing").sum() == n_in and (t.status == "spurious").sum() == np.sum(
        (moved.frequencies >= band[0]) & (moved.frequencies <= band[1]))
    t0 = ms.analysis.match_modes(full, red, band)
    assert (t0.status == "matched").sum() == np.sum(red.in_band) and (t0.status == "missing").sum() == n_in - np.sum(
        red.in_band)
    with pytest.raises(InputError, match="tol must be a positive number"):
        ms.analysis.match_modes(full, red, band, tol=0)


def test_mac_against_its_formula():
    rng = np.random.default_rng(3)
    n = 20
    X = rng.standard_normal((n, n))
    M = X @ X.T + n * np.eye(n)
    _, Phi = sla.eigh(np.diag(np.arange(1.0, n + 1)) + 0.1 * (X + X.T), M)
    err, tol = orthonormality_error(Phi, M)  # M-orthogonal modes: MAC I to rounding (measured 4e-16, bound 2e-12)
    assert_rounding(np.abs(ms.analysis.mac(Phi, Phi, M) - np.eye(n)).max(), 2 * tol, "MAC of M-orthonormal modes")
    A = rng.standard_normal((n, 3)) + 1j * rng.standard_normal((n, 3))
    B = rng.standard_normal((n, 4))
    ref = np.array([[abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b)) for b in B.T] for a in A.T])
    # |a^H b|^2 over n terms: its rounding relative to |a| |b| (cancellation), that of the MAC
    # rounding_unit(n) (2 sqrt(MAC) + MAC) entrywise: measured at most 0.015 of it
    bound = rounding_unit(n) * (2 * np.sqrt(ref) + ref)
    assert_rounding(np.max(np.abs(ms.analysis.mac(A, B) - ref) / bound), 1.0, "MAC / its rounding")
    assert_rounding(np.max(np.abs(ms.analysis.mac(A * (2 - 3j), B * -4.0) - ref) / bound), 1.0, "scale invariant")
    with pytest.raises(ShapeError, match="same n"):
        ms.analysis.mac(A, B[:-1])


def test_rom_modes_of_a_first_order_rom_lifts_its_positions(tcom):
    rom = ms.reducers.make("bt", tcom, form="first-order").reduce(6).rom
    m = ms.analysis.rom_modes(rom)
    assert m.shapes is not None and m.info["lift"] and m.shapes.shape == (tcom.n1, m.poles.size)
    lam, tol = eig_tolerance(rom.A, rom.E)  # passes with a tenth of it; tol 1e-15 .. 3e-15 (|poles| <= 0.43)
    up = lam.imag >= 0
    assert_sets_close(m.poles, lam[up], atol=tol[up], what="first-order poles")
    assert m.residuals.max() < 1e-10
    bare = ms.rom.FirstOrderROM(rom.E, rom.A, rom.B, rom.C)  # no lift: no shapes
    assert ms.analysis.rom_modes(bare).shapes is None


@pytest.mark.parametrize("method, options, r", [
    ("irka", {}, 6), ("irka-projected", {}, 6), ("irka-fo", {}, 12), ("bt", {}, 6),
    ("bt", {"form": "first-order"}, 12), ("bt-fl", {"band": (0.01, 1.0)}, 6), ("krylov", {}, 6),
    ("modal", {}, 6), ("so-h2", {}, 4)])
def test_every_projection_reducer_returns_its_lift(tcom, method, options, r):
    """The lift V (positions x = V q) lies on the hidden manifold (G V = 0, which the reducers do not
    impose on it directly) and reproduces the output map (L V = the ROM's output matrix); so-h2's
    reduced model is not a projection: no lift."""
    rom = ms.reducers.make(method, tcom, **options).reduce(r).rom
    if method == "so-h2":
        assert rom.basis is None
        return
    V = rom.basis
    assert V is not None and V.shape == (tcom.n1, rom.order) and np.isrealobj(V)
    G = tcom.G.toarray()
    # the constraint rows of the solves that built V (10: its orthogonalization), and products over n1 terms:
    # measured <= 7e-16 and 3e-16, bounds 10 rounding_unit(N) and rounding_unit(n1)
    N = tcom.n1 + tcom.n2
    assert_rounding(np.linalg.norm(G @ V) / (np.linalg.norm(G) * np.linalg.norm(V)), 10 * rounding_unit(N), "G V")
    C = rom.L if isinstance(rom, ms.rom.SecondOrderROM) else rom.C
    assert_rounding(np.linalg.norm(tcom.L @ V - C) / (np.linalg.norm(np.asarray(tcom.L)) * np.linalg.norm(V)),
                    rounding_unit(tcom.n1), "L V")


def test_irka_rom_mode_shapes_against_the_full_model(block):
    """IRKA interpolates two of the block's modes to rounding: on the simple one its lifted shape has
    MAC 1 with the full model's (1e-8); on a double pole the full shapes lie in the span of the lifted ones."""
    band = (0.5, 3.0)
    full = ms.analysis.model_modes(block, band)
    red = ms.analysis.rom_modes(ms.reducers.make("irka", block).reduce(10).rom, band)
    t = ms.analysis.match_modes(full, red, band)
    exact = t[(t.status == "matched") & (t.rel_freq_error < 1e-8)]
    assert len(exact) >= 2
    checked = 0
    for i, j in zip(exact.full_index, exact.rom_index):
        twins = np.flatnonzero(np.abs(full.frequencies - full.frequencies[i]) < 1e-6 * full.frequencies[i])
        rtwins = np.flatnonzero(np.abs(red.frequencies - red.frequencies[j]) < 1e-6 * red.frequencies[j])
        if twins.size == 1:
            assert abs(ms.analysis.mac(full.shapes[:, [i]], red.shapes[:, [j]])[0, 0] - 1) < 1e-8
            checked += 1
        elif rtwins.size == twins.size:
            Q, _ = np.linalg.qr(red.shapes[:, rtwins])
            X = full.shapes[:, twins]
            assert np.linalg.norm(X - Q @ (Q.conj().T @ X)) < 1e-8
            checked += 1
    assert checked >= 1


def test_structure_checks(block):
    rom = ms.reducers.make("modal", block).reduce(8).rom
    ok = ms.analysis.structure_checks(rom, block, omega=np.geomspace(0.1, 3, 8))
    assert ok["ok"] and ok["M_spd"] and ok["K_spd"] and ok["D_psd"] and ok["stable"] and ok["beats_zero"]
    K = rom.K.copy()
    K[0, 0] = -K[0, 0]  # an indefinite stiffness: unstable and not positive definite
    bad = ms.rom.SecondOrderROM(rom.M, rom.D, K, rom.F, rom.L)
    chk = ms.analysis.structure_checks(bad)
    assert not chk["K_spd"] and not chk["stable"] and not chk["ok"] and chk["beats_zero"] is None
    M = rom.M.copy()
    M[0, 1] += 1e-3  # asymmetric mass
    assert not ms.analysis.structure_checks(ms.rom.SecondOrderROM(M, rom.D, rom.K, rom.F, rom.L))["M_spd"]
    D = rom.D - 2 * np.abs(rom.D).max() * np.eye(rom.order)  # negative damping
    assert not ms.analysis.structure_checks(ms.rom.SecondOrderROM(rom.M, D, rom.K, rom.F, rom.L))["D_psd"]
    zero = ms.rom.SecondOrderROM(rom.M, rom.D, rom.K, 0 * rom.F, rom.L)
    assert ms.analysis.structure_checks(zero, block, omega=np.geomspace(0.1, 3, 8))["beats_zero"] is False


def test_modes_past_the_reach_of_lanczos_come_from_the_null_space(tcom):
    """k up to n1 - n2 - 1 at a shift above the whole spectrum (ARPACK error 3 at ncv = k + 1 on scipy 1.17):
    the dense null-space route, against the dense reference and against Lanczos where Lanczos fits."""
    w_ref, _ = dense_modes(tcom)
    limit = tcom.n1 - tcom.n2 - 1
    sigma = 1e6  # above every mode (the band (1e3, 2e3) of test_constrained_modes_refuses_bad_input)
    res = constrained_modes(tcom, k=limit, sigma=sigma)
    assert res.info["method"] == "dense" and res.info["status"] == "converged" and res.info["covered"]
    assert res.info["lu_count"] == 0 and res.omega.size == limit
    # the limit modes nearest sigma: all but the lowest
    assert_sets_close(res.omega, w_ref[1:], rtol=1e-10, what="modes nearest sigma")
    err, tol = orthonormality_error(res.shapes, tcom.M)
    assert err <= tol, (err, tol)
    # backward errors in the norm of the pencil (eigh is backward stable for Z^T K Z, not per mode: the
    # residual relative to ||K phi|| of a low mode grows with ||K|| / lambda; measured 5.5e-13 there)
    R = tcom.K @ res.shapes + tcom.G.T @ res.multipliers - (tcom.M @ res.shapes) * res.eigenvalues
    nK, nM = (np.linalg.norm(X.toarray(), 2) for X in (tcom.K, tcom.M))
    backward = np.linalg.norm(R, axis=0) / ((nK + np.abs(res.eigenvalues) * nM) * np.linalg.norm(res.shapes, axis=0))
    assert_rounding(backward.max(), 10 * rounding_unit(tcom.n1 + tcom.n2), "dense modes' backward errors")
    lan = constrained_modes(tcom, k=40, sigma=sigma)
    assert lan.info["method"] == "lanczos" and lan.info["status"] == "converged"
    assert_sets_close(lan.omega, w_ref[-40:], rtol=1e-10, what="Lanczos modes nearest sigma")
    # a band above the spectrum: its doubling k reaches the dense route, which covers the model and finds nothing
    with pytest.raises(InputError, match="holds no mode"):
        constrained_modes(tcom, band=(1e3, 2e3))
    # above dense_max, Lanczos keeps two spare basis vectors: k = n1 - n2 - 1 is refused with the reason
    with pytest.raises(InputError, match="leaves ARPACK no room"):
        constrained_modes(tcom, k=limit, sigma=sigma, dense_max=1)


def test_an_arpack_failure_falls_back_to_the_null_space_on_small_models(tcom, monkeypatch):
    import scipy.sparse.linalg as spla

    from morsuite.linalg import eigen

    def broken(*args, **kwargs):
        raise spla.ArpackError(3)

    monkeypatch.setattr(eigen.spla, "eigsh", broken)
    w_ref, _ = dense_modes(tcom)
    res = constrained_modes(tcom, k=6)
    assert res.info["method"] == "dense" and "ARPACK failed" in res.info["fallback"]
    assert_sets_close(res.omega, w_ref[:6], rtol=1e-10, what="lowest modes")
    with pytest.raises(spla.ArpackError):
        constrained_modes(tcom, k=6, dense_max=1)


def _partial_eigsh(converged):
    """scipy's eigsh, then ARPACK's no-convergence exception carrying only the pairs ``converged`` picks."""
    import scipy.sparse.linalg as spla

    real = spla.eigsh

    def eigsh(*args, **kwargs):
        lam, X = real(*args, **kwargs)
        keep = converged(lam.size)
        raise spla.ArpackNoConvergence("planted", lam[keep], X[:, keep])

    return eigsh


def test_partial_convergence_is_a_status_never_silent(tcom, monkeypatch):
    """ARPACK converging 4 of the 8 modes asked for (planted: the second, fourth, ... nearest) and a real
    run capped at one restart: status 'partial', covered False, a warning, and only modes of the model."""
    from morsuite.errors import ConvergenceWarning
    from morsuite.linalg import eigen

    w_ref, _ = dense_modes(tcom)
    with monkeypatch.context() as mp:
        mp.setattr(eigen.spla, "eigsh", _partial_eigsh(lambda n: np.arange(1, n, 2)))
        with pytest.warns(ConvergenceWarning, match="converged 4 of 8 modes"):
            res = constrained_modes(tcom, k=8)
    assert res.info["status"] == "partial" and not res.info["covered"] and res.info["k_converged"] == 4
    assert "modes nearer sigma may be missing" in res.info["reason"]
    assert_sets_close(res.omega, w_ref[1:8:2], rtol=1e-10, what="the planted converged modes")
    dsms = ms.models.dsms(g=100)
    with pytest.warns(ConvergenceWarning, match="of 12 modes"):
        real = constrained_modes(dsms, k=12, maxiter=1)
    assert real.info["status"] == "partial" and real.omega.size < 12
    w_dsms, _ = dense_modes(dsms)
    for w in real.omega:  # whatever converged is a mode of the model
        assert np.min(np.abs(w_dsms - w)) <= 1e-8 * w, w
