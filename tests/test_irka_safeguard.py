"""IRKA's safeguard against cycling and unstable fixed points (option ``safeguard``).

References are independent of the reducer: the full model's saddle-point transfer
function and its derivative (dense evaluation at the final shifts), a dense H2 norm of
the error system from the full model restricted to null(G) (Lyapunov equation), and
planted data for the building blocks. No test depends on an iteration count or on
which iterate a chaotic iteration happens to visit.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.reducers.base import as_complex
from support import assert_sets_close
from morsuite.reducers.irka.safeguards import CycleGuard, Shortlist, guard_weights, instability_culprit, \
    shift_slots
from morsuite.reducers.irka.shift_update import COMPLEX_TOL, relaxed_update, select_by_residue

EPS = np.finfo(float).eps


def _reduce(fom, r, **opts):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ms.reducers.make("irka", fom, **opts).reduce(r)


def _check_hermite(fom, res):
    """Hermite bitangential interpolation at the final shifts, each condition to 1e5 eps times
    the condition number of the reduced pencil at that shift."""
    rom, info = res.rom, res.info
    for a, b, c in zip(as_complex(info["shifts"]), as_complex(info["b"]), as_complex(info["c"])):
        T, Tr = fom.transfer(a), rom.transfer(a)
        dT, dTr = fom.transfer(a, derivative=True), rom.transfer_derivative(a)
        kappa = np.linalg.cond(a * a * rom.M + a * rom.D + rom.K)
        for x, y in ((T @ b, Tr @ b), (c @ T, c @ Tr), (c @ dT @ b, c @ dTr @ b)):
            x, y = np.atleast_1d(x), np.atleast_1d(y)
            assert np.linalg.norm(x - y) <= 1e5 * EPS * kappa * np.linalg.norm(x), (a, kappa)


def dense_h2_error(fom, rom) -> float:
    """H2 norm of T - Tr from dense matrices: the full model on null(G) (x = Z q, Z an
    orthonormal basis of null(G)) and the reduced model, both in first-order form, one
    Lyapunov equation for the error system. inf for an unstable reduced model."""
    if not rom.is_stable():
        return np.inf
    G = fom.G.toarray()
    Z = sla.null_space(G) if G.shape[0] else np.eye(fom.n1)

    def first_order(M, D, K, F, L):
        n = M.shape[0]
        Mi = np.linalg.inv(M)
        A = np.block([[np.zeros((n, n)), np.eye(n)], [-Mi @ K, -Mi @ D]])
        return A, np.vstack([np.zeros((n, F.shape[1])), Mi @ F]), np.hstack([L, np.zeros((L.shape[0], n))])

    Af, Bf, Cf = first_order(Z.T @ fom.M.toarray() @ Z, Z.T @ fom.D.toarray() @ Z, Z.T @ fom.K.toarray() @ Z,
                             Z.T @ fom.F, fom.L @ Z)
    Ar, Br, Cr = first_order(rom.M, rom.D, rom.K, rom.F, rom.L)
    A = sla.block_diag(Af, Ar)
    B, C = np.vstack([Bf, Br]), np.hstack([Cf, -Cr])
    P = sla.solve_continuous_lyapunov(A, -B @ B.T)
    return float(np.sqrt(max(np.trace(C @ P @ C.T), 0.0)))


# -- convergence where the plain iteration does not converge -----------------------------------
@pytest.mark.parametrize("nc", [40, 50])
def test_unstable_fixed_point_is_left_and_a_stable_one_reached(nc):
    """io=points, r = 4: the plain iteration settles at shifts whose reduced model has a
    spurious unstable pole (measured: 100 iterations, not converged, on nc = 40..54); the
    safeguard bans the shift whose removal stabilises the model and converges."""
    fom = ms.models.tcom(nc=nc, constraints="curvature", io="points")
    res = _reduce(fom, 4)
    info = res.info
    assert info["converged"] and info["stable"] and res.rom.is_stable()
    assert info["r"] == 4
    _check_hermite(fom, res)


def test_selection_cycle_of_the_residue_rule_is_broken():
    """The residue rule without hysteresis swaps poles of near-equal score in and out of the
    chosen set (measured on tcom(nc=40), r = 8: a cycle detected after 8 iterations); with the
    safeguard on, matched hysteresis keeps one of the competing poles and the iteration converges."""
    fom = ms.models.tcom(nc=40)
    res = _reduce(fom, 8, update="residue", residue_hysteresis=0.0, safeguard="on")
    assert res.info["converged"] and res.info["stable"]
    _check_hermite(fom, res)


def test_off_reproduces_the_plain_iteration_up_to_where_the_safeguard_engages():
    """Same process, same model: with safeguard="off" the iteration is the plain one; with it on,
    the shift history is the same, bit for bit, up to the iteration at which it engaged, and the
    plain run stops there on its cycle test (the old behaviour)."""
    fom = ms.models.tcom(nc=40)
    opts = {"update": "residue", "residue_hysteresis": 0.0}
    off = _reduce(fom, 8, safeguard="off", **opts).info
    on = _reduce(fom, 8, safeguard="on", **opts).info
    eng = on["safeguard"]["engaged_at"]
    if eng is None:  # nothing went wrong: the two runs are the same
        assert off["converged"] and on["converged"] and off["history"]["shifts"] == on["history"]["shifts"]
        return
    assert on["safeguard"]["reason"] in ("cycle", "stall", "unstable fixed point")
    assert off["history"]["shifts"][:eng] == on["history"]["shifts"][:eng]
    assert off["safeguard"]["active"] is False and off["safeguard"]["engaged_at"] is None
    if on["safeguard"]["reason"] == "cycle":
        assert off["cycle_detected"] and off["iterations"] == eng and not off["converged"]


@pytest.mark.parametrize("spec, r", [("tcom:nc=40", 6), ("dsms:g=300", 6)])
def test_where_it_converges_the_safeguard_changes_nothing(spec, r):
    fom = ms.models.parse(spec)
    # the first reduction on a model in a process differs from later ones at rounding level
    # (a cache of the model, also on main): compare two later ones
    _reduce(fom, r)
    a, b = _reduce(fom, r), _reduce(fom, r, safeguard="off")
    assert a.info["converged"] and a.info["safeguard"]["engaged_at"] is None
    for f in ("M", "D", "K", "F", "L"):
        assert np.array_equal(getattr(a.rom, f), getattr(b.rom, f))
    assert a.info["history"]["shifts"] == b.info["history"]["shifts"]


def test_explicit_update_rule_leaves_the_safeguard_off_unless_asked():
    fom = ms.models.tcom(nc=20)
    assert _reduce(fom, 4, update="bt").info["safeguard"]["active"] is False
    assert _reduce(fom, 4, update="bt", safeguard="on").info["safeguard"]["active"] is True
    assert _reduce(fom, 4).info["safeguard"]["active"] is True


# -- without convergence: the best stable iterate, scored ----------------------------------------
def test_nonconvergence_returns_the_stable_iterate_of_smallest_dense_h2_error():
    fom = ms.models.tcom(nc=40, constraints="curvature", io="points")
    red = ms.reducers.make("irka", fom, maxit=8, tol=1e-12)
    calls = []

    def score(f, rom):
        calls.append(rom)
        return dense_h2_error(f, rom)

    red.iterate_score = score
    with pytest.warns(ms.ConvergenceWarning, match="did not converge"):
        res = red.reduce(6)
    info = res.info
    assert info["converged"] is False
    hist = info["history"]
    n_stable = sum(hist["stable"])
    assert n_stable >= 1  # the premise: some iterate is stable
    assert info["stable"] and res.rom.is_stable()
    scores = {int(k): v for k, v in info["safeguard"]["scores"].items()}
    assert info["safeguard"]["scored_by"] == "iterate_score"
    assert 1 <= len(scores) == len(calls) <= min(n_stable, info["options"]["shortlist"])
    assert all(hist["stable"][i - 1] for i in scores)
    assert scores[info["best_iteration"]] == min(scores.values())
    assert dense_h2_error(fom, res.rom) == pytest.approx(min(scores.values()), rel=1e-12)
    # the shortlist holds the stable iterates of smallest measure
    stable_measures = sorted(m for m, s in zip(hist["measure"], hist["stable"]) if s)
    assert sorted(hist["measure"][i - 1] for i in scores) == stable_measures[:len(scores)]


def test_dense_h2_reference_scorer_agrees_with_quadrature():
    """The test's own reference: the Lyapunov H2 error against trapezoidal quadrature of
    ||T - Tr||_F^2 on the imaginary axis (a smooth, well damped case)."""
    fom = ms.models.dsms(60)
    rom = _reduce(fom, 3).rom

    def quad(per_decade):
        # composite 8-point Gauss-Legendre in log w on [1e-6, 1e3] (per_decade panels a decade), the
        # trapezoid on [0, 1e-6]; the error response is smooth (poles damped at zeta >= 0.2)
        x, wt = np.polynomial.legendre.leggauss(8)
        edges = np.linspace(np.log(1e-6), np.log(1e3), 9 * per_decade + 1)
        a, b = edges[:-1, None], edges[1:, None]
        w = np.exp(((a + b) / 2 + (b - a) / 2 * x).ravel())
        weight = ((b - a) / 2 * wt).ravel() * w          # dw = w d(log w)
        f = [np.sum(np.abs(fom.freqresp(v) - rom.freqresp(v)) ** 2, axis=(1, 2)) for v in (w, [0.0, 1e-6])]
        return np.sqrt((weight @ f[0] + np.trapezoid(f[1], [0.0, 1e-6])) / np.pi)

    # (720 nodes; the trapezoid on 40001 log-spaced points took 20x longer for 1e-4.) The rule's own
    # accuracy: at half the panels it agrees to 7e-9 (measured), at these to 3e-12 of the dense value
    fine, coarse = quad(10), quad(5)
    assert abs(fine - coarse) <= 1e-7 * fine
    assert dense_h2_error(fom, rom) == pytest.approx(fine, rel=1e-7)


def test_shortlist_prefers_stable_then_score_then_earlier():
    # payloads are (rom, shifts, b, c); the score is called with the rom
    s = Shortlist(2)
    s.add(1e-3, 1, False, ("u1",))   # smallest measure, unstable
    s.add(5e-2, 2, True, ("s2",))
    s.add(1e-2, 3, True, ("s3",))
    s.add(2e-2, 4, True, ("s4",))   # pushes s2 out of a shortlist of 2
    it, payload, scores = s.choose()
    assert (it, payload, scores) == (3, ("s3",), {})
    it, payload, scores = s.choose(lambda rom: {"s3": 2.0, "s4": 1.0}[rom])
    assert (it, payload) == (4, ("s4",)) and scores == {3: 2.0, 4: 1.0}
    it, _, _ = s.choose(lambda rom: 1.0)  # tie: the smaller measure
    assert it == 3
    only_unstable = Shortlist(3)
    only_unstable.add(0.5, 1, False, ("a",))
    only_unstable.add(0.1, 2, False, ("b",))
    assert only_unstable.choose(lambda rom: 0.0)[:2] == (2, ("b",))


# -- building blocks ------------------------------------------------------------------------------
def test_matched_hysteresis_favours_one_pole_per_shift_and_tabu_passes_over():
    # two pole pairs near the shifts 1 +- 10j (a near-double resonance), one near 2 +- 20j
    lam = np.array([-1 + 10j, -1 - 10j, -1.02 + 10.05j, -1.02 - 10.05j, -2 + 20j, -2 - 20j, -5 + 0j])
    cur = np.array([1 + 10j, 1 - 10j, 2 + 20j, 2 - 20j])
    w = guard_weights(lam, cur, hysteresis=1.0, radius=0.05)
    assert list(w) == [2.0, 2.0, 1.0, 1.0, 2.0, 2.0, 1.0]
    # one slot pair: the radius rule of select_by_residue favours both near-double pairs and
    # the higher score wins; matched hysteresis keeps the pair in use
    b = np.ones((7, 1))
    c = np.array([[1.0], [1.0], [1.3], [1.3], [0.1], [0.1], [0.1]]) * np.sqrt(2 * np.abs(lam.real))[:, None]
    assert sorted(select_by_residue(lam, b, c, 2, current=cur, hysteresis=1.0, radius=0.05)) == [2, 3]
    assert sorted(select_by_residue(lam, b, c, 2, weights=w)) == [0, 1]
    # tabu: a banned shift (given by either member of its conjugate pair) is passed over
    wt = guard_weights(lam, cur, hysteresis=0.0, radius=0.05, tabu=[1 - 10j], tabu_radius=0.002)
    assert np.all(wt[:2] < 1e-10) and np.all(wt[2:] == 1.0)
    # an unstable pole is compared by its mirror image
    assert guard_weights(np.array([2 + 20j]), np.array([2 - 20j]), 1.0, 0.05)[0] == 2.0


def test_blended_relaxation_keeps_fixed_points_and_ignores_direction_phase():
    rng = np.random.default_rng(1)
    alpha = np.array([0.5, 1 + 2j, 1 - 2j])
    b = rng.standard_normal((3, 2)) + 1j * rng.standard_normal((3, 2))
    b[0] = b[0].real
    b[2] = np.conj(b[1])
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    c = b[:, ::-1].copy()
    # a fixed point of the plain update is one of the relaxed update
    a2, b2, c2 = relaxed_update(alpha, b, c, alpha, b, c, 0.3, blend_directions=True)
    order = np.lexsort((alpha.imag, alpha.real))
    assert np.allclose(a2, alpha[order]) and np.allclose(b2, b[order]) and np.allclose(c2, c[order])
    # new directions given with another phase: the same relaxed directions
    nb = np.roll(b, 1, axis=1)
    nb[2] = np.conj(nb[1])
    nb /= np.linalg.norm(nb, axis=1, keepdims=True)
    ph = np.exp(1j * np.array([0.0, 0.7, -0.7]))
    x = relaxed_update(alpha, b, c, alpha * 1.1, nb, c, 0.5, blend_directions=True)
    y = relaxed_update(alpha, b, c, alpha * 1.1, nb * ph[:, None], c, 0.5, blend_directions=True)
    assert np.allclose(x[0], y[0]) and np.allclose(x[1], y[1])
    assert np.allclose(np.linalg.norm(x[1], axis=1), 1.0)
    # conjugate pairs stay pairs
    k = np.abs(x[0].imag) > COMPLEX_TOL
    # the same formula on conjugate inputs: measured exact conjugates
    assert_sets_close(x[0][k], np.conj(x[0][k]), rtol=1e-12, what="the shifts and their conjugates")


def test_shift_slots_follow_the_basis_column_order():
    alpha = np.array([0.3, 1 - 1j, 1 + 1j, 2.0, 3 + 1j, 3 - 1j])
    slots = shift_slots(alpha, COMPLEX_TOL)
    assert [(sorted(s), c) for s, c in slots] == [([0], [0]), ([1, 2], [1, 2]), ([3], [3]), ([4, 5], [4, 5])]


def test_instability_culprit_is_the_removal_that_stabilises():
    class Rom:
        def __init__(self, poles):
            self._p = np.asarray(poles, dtype=complex)

        def poles(self):
            return self._p

    slots = [([0], [0]), ([1, 2], [1, 2]), ([3], [3])]
    planted = {0: [0.1 + 1j, -1], 1: [-0.5, -1], 2: None}  # removing slot 1 leaves a stable model
    s, val = instability_culprit(slots, lambda cols: None if planted[cols[0] if cols[0] < 3 else 2] is None
                                 else Rom(planted[{0: 0, 1: 1, 3: 2}[cols[0]]]))
    assert s == 1 and val == pytest.approx(-1.0)


def test_guard_state_engages_bans_and_adapts_its_step():
    g = CycleGuard(True, hysteresis=1.0, radius=0.05, settle=1e-3, window=3, min_step=0.125, tabu_radius=0.01)
    assert not g.engaged and g.step == 1.0
    for m in (1.0, 0.5, 0.6, 0.7):
        g.observe(m)
    assert not g.stalled()
    g.observe(0.8)
    assert g.stalled()
    g.engage(7, "stall")
    assert g.engaged and g.info()["reason"] == "stall"
    assert g.adapt_step(0.2, 0.1) == 0.5 and g.adapt_step(0.3, 0.2) == 0.25
    assert g.adapt_step(0.1, 0.3) == 0.5
    for _ in range(5):
        g.adapt_step(1.0, 0.1)
    assert g.step == 0.125
    g.on_cycle(9)
    assert g.h == 4.0
    g.ban(10, 2 - 3j, -0.1)
    assert g.tabu == [2 + 3j] and any("banned" in e for e in g.info()["events"])


# -- options ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("opts, match", [
    ({"safeguard": "yes"}, "The 'safeguard' parameter of IRKA must be one of"),
    ({"safeguard_min_step": 0.0}, "The 'safeguard_min_step' parameter of IRKA must be a float in"),
    ({"safeguard_window": 1}, "The 'safeguard_window' parameter of IRKA must be an int in"),
    ({"safeguard_settle": 1.0}, "The 'safeguard_settle' parameter"),
    ({"shortlist": 0}, "The 'shortlist' parameter"),
])
def test_bad_safeguard_options_are_refused(opts, match):
    with pytest.raises(ms.OptionError, match=match):
        ms.reducers.make("irka", ms.models.dsms(50), **opts)


def test_safeguard_options_and_record_are_in_info():
    info = _reduce(ms.models.tcom(nc=20), 4, safeguard="off", shortlist=3).info
    assert info["options"]["safeguard"] == "off" and info["options"]["shortlist"] == 3
    assert set(info["safeguard"]) >= {"active", "engaged_at", "reason", "tabu", "events", "scored_by", "scores"}
    assert len(info["history"]["step"]) == info["iterations"]
