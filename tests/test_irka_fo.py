"""First-order tangential IRKA (``irka-fo``): interpolation, a dense projected reference, H2, options.

References are independent of the reducer: the index-3 model projected densely onto an
orthonormal basis of null(G) (``scipy.linalg.null_space``) and written in first-order
form, dense tangential IRKA on it (written here), dense Lyapunov H2 norms of error
systems, and dense evaluations of the reduced matrices.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.errors import ConvergenceWarning, InputError, OptionError
from morsuite.reducers.base import as_complex
from morsuite.reducers.irka.surrogate import Chart, ModalSurrogate, newton_fixed_point, SurrogateMap
from morsuite.linalg.dense import match_sets
from support import assert_sets_close, eig_tolerance

EPS = np.finfo(float).eps
MIMO = "tcom:nc=20,constraints=curvature,io=points"


def _reduce(fom, r, **opts):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ms.reducers.make("irka-fo", fom, **opts).reduce(r)


class Projected:
    """The model on null(G) in first-order form: E = blkdiag(I, Mp), A = [[0, I], [-Kp, -Dp]], dense."""

    def __init__(self, fom):
        Z = sla.null_space(fom.G.toarray()) if fom.n2 else np.eye(fom.n1)
        Mp, Dp, Kp = (Z.T @ (X.toarray() @ Z) for X in (fom.M, fom.D, fom.K))
        k = Z.shape[1]
        I, O = np.eye(k), np.zeros((k, k))
        self.E = np.block([[I, O], [O, Mp]])
        self.A = np.block([[O, I], [-Kp, -Dp]])
        self.B = np.vstack([np.zeros((k, fom.m)), Z.T @ fom.F])
        self.C = np.hstack([fom.L @ Z, np.zeros((fom.p, k))])

    def transfer(self, s):
        return self.C @ np.linalg.solve(s * self.E - self.A, self.B)

    def derivative(self, s):
        P = s * self.E - self.A
        return -self.C @ np.linalg.solve(P, self.E @ np.linalg.solve(P, self.B))


def h2_dense(E, A, B, C):
    """||C (sE - A)^-1 B||_H2 from the dense controllability Gramian."""
    Ai, Bi = np.linalg.solve(E, A), np.linalg.solve(E, B)
    P = sla.solve_continuous_lyapunov(Ai, -Bi @ Bi.T)
    return float(np.sqrt(max(np.trace(C @ P @ C.T), 0.0)))


def h2_error_dense(proj, rom):
    n, k = proj.A.shape[0], rom.A.shape[0]
    E = sla.block_diag(proj.E, rom.E)
    A = sla.block_diag(proj.A, rom.A)
    return h2_dense(E, A, np.vstack([proj.B, rom.B]), np.hstack([proj.C, -rom.C]))


def hermite_mismatch(proj, rom, shifts, bdir, cdir):
    """Largest relative mismatch of T b, c^T T, c^T T' b at each shift (dense evaluation)."""
    worst = 0.0
    for a, b, c in zip(shifts, bdir, cdir):
        T, Tr = proj.transfer(a), rom.transfer(a)
        d, dr = c @ proj.derivative(a) @ b, c @ rom.transfer_derivative(a) @ b
        for x, y in ((T @ b, Tr @ b), (c @ T, c @ Tr), (d, dr)):
            worst = max(worst, np.linalg.norm(np.atleast_1d(x - y)) / np.linalg.norm(np.atleast_1d(x)))
    return worst


def modal(rom):
    lam, X = sla.eig(rom.A, rom.E)
    return lam, np.linalg.solve(rom.E @ X, rom.B), rom.C @ X


# -- interpolation, optimality -------------------------------------------------
@pytest.mark.parametrize("spec, r", [("tcom:nc=20", 8), (MIMO, 10)], ids=["siso-tcom20-r8", "mimo3x3-r10"])
def test_converged_rom_interpolates_at_its_shifts_and_at_its_mirrored_poles(spec, r):
    fom = ms.models.parse(spec)
    proj = Projected(fom)
    res = _reduce(fom, r)
    info, rom = res.info, res.rom
    assert info["converged"], info["warnings"]
    assert info["kind"] == "first-order" and info["r"] == info["states"] == r == rom.A.shape[0]
    # Hermite bitangential interpolation at the data the ROM was built at (by construction)
    assert hermite_mismatch(proj, rom, as_complex(info["shifts"]), as_complex(info["b"]),
                            as_complex(info["c"])) < 1e-8
    # H2 optimality: the same conditions at its mirrored poles with its residue directions
    lam, bres, cres = modal(rom)
    a = -lam
    mism = hermite_mismatch(proj, rom, a, bres, cres.T)
    # the certificate scales the derivative mismatch by Re(a)/|a|; the unscaled one is at most |a|/Re(a) larger
    assert mism <= info["certificate"]["tol"] * np.max(np.abs(a) / a.real)
    assert info["certificate"]["residual"] <= info["certificate"]["tol"]


@pytest.mark.parametrize("maxit", [3, 100], ids=["early-iterate", "fixed-point"])
def test_certificate_is_the_dense_interpolation_residual_at_the_mirrored_poles(maxit):
    fom = ms.models.parse(MIMO)
    proj = Projected(fom)
    res = _reduce(fom, 6, strategy="plain", maxit=maxit)
    rom = res.rom
    lam, bres, cres = modal(rom)
    worst = 0.0
    for a, b, c in zip(-lam, bres, cres.T):
        b, c = b / np.linalg.norm(b), c / np.linalg.norm(c)
        T, Tr = proj.transfer(a), rom.transfer(a)
        d, dr = c @ proj.derivative(a) @ b, c @ rom.transfer_derivative(a) @ b
        worst = max(worst, np.linalg.norm(T @ b - Tr @ b) / np.linalg.norm(T @ b),
                    np.linalg.norm(c @ T - c @ Tr) / np.linalg.norm(c @ T), abs(d - dr) / abs(d) * a.real / abs(a))
    cert = res.info["certificate"]["residual"]
    # an early iterate: a definite mismatch, computed two ways; a fixed point: both at rounding level
    assert cert == pytest.approx(worst, rel=1e-6) if worst > 1e-6 else max(cert, worst) < 1e-6
    assert (cert <= res.info["certificate"]["tol"]) == res.info["converged"]


# -- the dense reference iteration ----------------------------------------------
def dense_irka(proj, alpha, bdir, cdir, iterations):
    """Tangential IRKA on the dense projected first-order model; the shift sets of every iteration."""
    out, tols = [], [None]
    for _ in range(iterations):
        out.append(alpha)
        V, W = [], []
        for a, b, c in zip(alpha, bdir, cdir):
            if a.imag < 0:
                continue
            v = np.linalg.solve(a * proj.E - proj.A, proj.B @ b)
            w = np.linalg.solve((a * proj.E - proj.A).T, proj.C.T @ c)
            V += [v.real, v.imag] if a.imag > 0 else [v.real]
            W += [w.real, w.imag] if a.imag > 0 else [w.real]
        V, W = np.linalg.qr(np.array(V).T)[0], np.linalg.qr(np.array(W).T)[0]
        Er, Ar = W.T @ proj.E @ V, W.T @ proj.A @ V
        lam, X = sla.eig(Ar, Er)
        tols.append(_pole_tol(Ar, Er, lam))
        bres, cres = np.linalg.solve(Er @ X, W.T @ proj.B), (proj.C @ V @ X).T
        alpha = -lam
        alpha = np.where(alpha.real < 0, -alpha.real + 1j * alpha.imag, alpha)  # unstable poles mirrored
        bdir = bres / np.linalg.norm(bres, axis=1, keepdims=True)
        cdir = cres / np.linalg.norm(cres, axis=1, keepdims=True)
    return out, tols[:iterations], (Er, Ar, W.T @ proj.B, proj.C @ V)


def _pole_tol(Ar, Er, lam):
    """eig_tolerance's bound for each of lam (matched to its own eigenvalues)."""
    lam_t, tol = eig_tolerance(Ar, Er)
    perm, _ = match_sets(lam, lam_t)
    return tol[perm]


@pytest.mark.parametrize("spec, r", [("tcom:nc=20", 6), (MIMO, 6)], ids=["siso", "mimo"])
def test_same_iterates_as_dense_irka_on_the_projected_model(spec, r):
    fom = ms.models.parse(spec)
    proj = Projected(fom)
    rng = np.random.default_rng(3)
    alpha = np.logspace(-2, 0, r).astype(complex)
    b, c = rng.standard_normal((r, fom.m)), rng.standard_normal((r, fom.p))
    its = 4
    res = _reduce(fom, r, strategy="plain", init="given", init_shifts=alpha, init_b=b, init_c=c, maxit=its,
                  tol=1e-15, cycle_window=0)
    ours = [as_complex(s) for s in res.info["history"]["shifts"]]
    ref, tols, last = dense_irka(proj, alpha, b.astype(complex), c.astype(complex), its)
    assert len(ours) == its
    # each set is the mirrored poles of the previous reduced model; the two reduced models differ by the
    # rounding of two different orthonormalisations of bases whose condition numbers reach 1e3-1e4 on these
    # chain models (localised solutions): 1e4 times the eigenvalue bound (measured: 1e-12 relative)
    lam_last, tol_last = eig_tolerance(last[1], last[0])
    for j in range(1, its):
        assert_sets_close(ours[j], ref[j], atol=1e4 * tols[j], what=f"shifts of iteration {j + 1}")
    k = res.info["returned_iteration"]
    assert 1 <= k <= its
    rom = res.rom
    s = 0.3j + 0.05
    if k == its:
        Tr_ref = last[3] @ np.linalg.solve(s * last[0] - last[1], last[2])
        assert np.linalg.norm(rom.transfer(s) - Tr_ref) <= 1e-7 * np.linalg.norm(Tr_ref)
        assert_sets_close(rom.poles(), lam_last, atol=1e4 * tol_last, what="poles")


# -- H2 -----------------------------------------------------------------------
@pytest.mark.parametrize("spec, r", [("tcom:nc=30", 8), ("tcom:nc=30", 14), (MIMO, 10)],
                         ids=["tcom30-r8", "tcom30-r14", "mimo-r10"])
def test_h2_error_at_or_below_first_order_bt_and_tracked_exactly(spec, r):
    fom = ms.models.parse(spec)
    proj = Projected(fom)
    res = _reduce(fom, r)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bt = ms.reducers.make("bt", fom).reduce(r).rom
    e_fo, e_bt = h2_error_dense(proj, res.rom), h2_error_dense(proj, bt)
    assert res.info["converged"]
    assert e_fo <= e_bt * (1 + 1e-8)
    # the tracked value against the dense Lyapunov one: both lose (||T|| / e)^2 eps to cancellation
    norm = h2_dense(proj.E, proj.A, proj.B, proj.C)
    tol = 1e3 * EPS * (norm / e_fo) ** 2 + 1e-10
    assert res.info["h2_error"] == pytest.approx(e_fo, rel=tol)
    assert res.info["norm"] == pytest.approx(norm, rel=1e-10)


def test_plain_iteration_cycles_where_the_surrogate_strategy_converges():
    fom = ms.models.parse("tcom:nc=20")
    proj = Projected(fom)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        plain = ms.reducers.make("irka-fo", fom, strategy="plain", maxit=60).reduce(14)
    assert not plain.info["converged"]
    # the engine's status, kept (test_statuses_are_the_engines)
    assert plain.info["status"] == ("cycle" if plain.info["cycle_detected"] else
                                    "uncertified" if plain.info["engine_converged"] else "cap")
    assert any(issubclass(w.category, ConvergenceWarning) for w in caught)
    assert plain.rom.is_stable()
    # the returned iterate is the one of smallest exact H2 error among those tracked
    hist = [h for h in plain.info["h2_history"] if h is not None]
    assert plain.info["h2_error"] <= min(hist) * (1 + 1e-6)
    assert plain.info["h2_error"] <= plain.info["start"]["h2_error"]
    sur = _reduce(fom, 14)
    info = sur.info
    assert info["converged"] and info["returned_is_last"] and info["status"] == "converged"
    assert info["surrogate"]["relaxed_from"] is not None  # the surrogate's plain iteration did not converge
    assert info["certificate"]["residual"] <= info["certificate"]["tol"]
    # a few full-model iterations only
    assert info["iterations"] <= 5
    e = h2_error_dense(proj, sur.rom)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        e_bt = h2_error_dense(proj, ms.reducers.make("bt", fom).reduce(14).rom)
    assert e <= e_bt


# -- the surrogate's pieces -------------------------------------------------------
def test_chart_round_trip_and_surrogate_interpolant():
    rng = np.random.default_rng(0)
    m, p = 3, 2
    up = rng.uniform(0.1, 1, 3) + 1j * rng.uniform(0.1, 2, 3)
    alpha = np.concatenate([up, up.conj(), [0.7]])
    b = rng.standard_normal((3, m)) + 1j * rng.standard_normal((3, m))
    c = rng.standard_normal((3, p)) + 1j * rng.standard_normal((3, p))
    bdir = np.vstack([b, b.conj(), rng.standard_normal((1, m))])
    cdir = np.vstack([c, c.conj(), rng.standard_normal((1, p))])
    chart = Chart.at(alpha, bdir, cdir)
    x = chart.encode(alpha, bdir, cdir)
    assert x.size == chart.size
    a2, b2, c2 = chart.decode(x)
    assert_sets_close(a2, alpha, rtol=1e-15, what="shifts")  # stored as they are: measured equal
    # the same directions up to a complex factor: the decoded ones are proportional
    for a, bb, cc in zip(alpha, bdir, cdir):
        i = int(np.argmin(np.abs(a2 - a)))
        for u, v in ((bb, b2[i]), (cc, c2[i])):
            # Cauchy-Schwarz's equality on 2 or 3 entries (no solve): measured 3e-16 relative
            assert abs(abs(np.vdot(u, v)) - np.linalg.norm(u) * np.linalg.norm(v)) < 1e-12 * np.linalg.norm(v) ** 2
    assert np.allclose(chart.encode(a2[::-1], b2[::-1], c2[::-1]), x, rtol=1e-14, atol=1e-14)  # measured equal
    # the interpolant of a random stable surrogate interpolates it (dense check)
    n = 12
    A = rng.standard_normal((n, n)) - 6 * np.eye(n)
    sur_rom = ms.rom.FirstOrderROM(None, A, rng.standard_normal((n, m)), rng.standard_normal((p, n)))
    sur = ModalSurrogate(sur_rom)
    rom = sur.interpolant(alpha, bdir, cdir)
    for a, bb, cc in zip(alpha, bdir, cdir):
        T, Tr = sur_rom.transfer(a), rom.transfer(a)
        assert np.linalg.norm(T @ bb - Tr @ bb) <= 1e-10 * np.linalg.norm(T @ bb)
        assert np.linalg.norm(cc @ T - cc @ Tr) <= 1e-10 * np.linalg.norm(cc @ T)
    # a fixed point found by Newton satisfies the interpolation conditions at its mirrored poles
    smap = SurrogateMap(sur, (0.1, 10.0))
    res = newton_fixed_point(smap, alpha, bdir, cdir, tol=1e-11)
    assert res.converged  # measured: 11 Newton steps from this seeded start (tol 1e-11)
    rom = sur.interpolant(*res.data)
    lam, bres, cres = modal(rom)
    for a, bb, cc in zip(-lam, bres, cres.T):
        assert abs(cc @ (sur_rom.transfer_derivative(a) - rom.transfer_derivative(a)) @ bb) <= \
            1e-6 * abs(cc @ sur_rom.transfer_derivative(a) @ bb)


# -- options, info, registry ------------------------------------------------------
@pytest.mark.parametrize("opts, match", [
    ({"strategy": "newton"}, "strategy"), ({"update": "bt"}, "update"), ({"init": "pole"}, "init"),
    ({"certificate_tol": 2.0}, "certificate_tol"), ({"surrogate_states": -1}, "surrogate_states"),
    ({"surrogate_relaxation": 0.0}, "surrogate_relaxation"), ({"newton_starts": 0}, "newton_starts"),
    ({"track_h2": 1}, "track_h2"), ({"sigma": 1}, "unknown option")])
def test_bad_options_are_refused(tcom20, opts, match):
    with pytest.raises(OptionError, match=match):
        ms.reducers.make("irka-fo", tcom20, **opts)


def test_bad_r_is_refused_with_the_state_count(dsms50):
    red = ms.reducers.make("irka-fo", dsms50)
    with pytest.raises(InputError, match="first-order states"):
        red.reduce(2 * (dsms50.n1 - dsms50.n2) + 1)
    with pytest.raises(InputError):
        red.reduce(0)


def test_registry_info_and_reuse(tcom20):
    assert "irka-fo" in ms.reducers.available()
    red = ms.reducers.make("irka-fo", tcom20)
    a = _reduce(tcom20, 5, strategy="plain")
    info = a.info
    json.dumps(info)
    assert info["kind"] == "first-order" and info["r"] == info["states"] == 5  # an odd number of states
    assert info["options"]["strategy"] == "plain" and info["options"]["init"] == "bt"
    for key in ("h2_error", "h2_history", "certificate", "start", "returned_iteration", "engine_converged"):
        assert key in info
    assert len(info["h2_history"]) == info["iterations"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        red.reduce(6)
        second = red.reduce(8).info
    # the BT start's Gramian factors and SVD are reused across r
    assert second["start"]["gramians_reused"] and second["start"]["lu_count"] == 0


def test_without_h2_tracking_the_certificate_still_decides(tcom20):
    res = _reduce(tcom20, 6, strategy="plain", init="logspace", track_h2=False)
    info = res.info
    assert info["h2_error"] is None and all(h is None for h in info["h2_history"])
    assert info["converged"] == (info["engine_converged"] and info["certificate"]["residual"] <= 1e-4)
    assert info["certificate"]["residual"] is not None
    assert not set(tcom20.cache) - {"rigid_modes"}  # no Gramian factors were computed (the rigid-mode check is)



def test_statuses_are_the_engines():
    """irka-fo keeps the IRKA engine's status (reducers.outcome.STATUS): ``cap`` at maxit, ``uncertified``
    where the engine's fixed-point test held and the certificate failed (certificate_tol below the
    fixed point's residual), ``cycle`` on a detected cycle; never ``stalled``, which it once wrote
    over the last two."""
    early = _reduce(ms.models.parse(MIMO), 6, strategy="plain", maxit=3).info
    assert not early["engine_converged"] and not early["cycle_detected"] and early["status"] == "cap"
    tcom = ms.models.parse("tcom:nc=20")
    # the surrogate strategy's fixed point at r = 14 (converged and certified at the default tolerance:
    # test_plain_iteration_cycles_where_the_surrogate_strategy_converges), held to a certificate_tol
    # below its residual
    strict = _reduce(tcom, 14, certificate_tol=1e-15).info
    assert strict["engine_converged"] and strict["certificate"]["residual"] > 1e-15
    assert not strict["converged"] and strict["status"] == "uncertified"
    # cycle: test_plain_iteration_cycles_where_the_surrogate_strategy_converges
