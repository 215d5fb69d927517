"""Time-domain simulation: against the dense hidden-manifold model, orders, energy, ROM paths, H2 bound.

References are independent of the code under test: the explicit null-space basis
N of G (scipy.linalg.null_space), the projected dense ODE and python-control's
forced_response (exact for inputs linear between samples, so exact for a step).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

import morsuite as ms
from morsuite.analysis import output_errors, signals, simulate
from morsuite.errors import InputError, OptionError, StabilityWarning
from support import assert_rounding, solve_tolerance

control = pytest.importorskip("control")
EPS = np.finfo(float).eps


def hidden_manifold(fom):
    """Dense projected model on ker G: (N, (M, D, K, F, L), first-order control.ss)."""
    N = sla.null_space(fom.G.toarray()) if fom.n2 else np.eye(fom.n1)
    M, D, K = (N.T @ X.toarray() @ N for X in (fom.M, fom.D, fom.K))
    F, L = N.T @ fom.F, fom.L @ N
    k = N.shape[1]
    A = np.block([[np.zeros((k, k)), np.eye(k)], [-np.linalg.solve(M, K), -np.linalg.solve(M, D)]])
    B = np.vstack([np.zeros((k, fom.m)), np.linalg.solve(M, F)])
    C = np.hstack([L, np.zeros((fom.p, k))])
    return N, (M, D, K, F, L), control.ss(A, B, C, np.zeros((fom.p, fom.m)))


def reference(sys, t, U, x0=None):
    """Exact response (input linear between samples) and states of a dense control.ss."""
    r = control.forced_response(sys, T=t, U=U.T, X0=0.0 if x0 is None else x0, return_states=True,
                                squeeze=False)
    return np.asarray(r.outputs).reshape(-1, t.size).T, np.asarray(r.states).T


def modal_rom(fom, r):
    """Second-order Galerkin ROM on the r lowest undamped modes of the hidden-manifold model."""
    N, (M, D, K, F, L), _ = hidden_manifold(fom)
    _, X = sla.eigh(K, M, subset_by_index=[0, r - 1])
    return ms.rom.SecondOrderROM(X.T @ M @ X, X.T @ D @ X, X.T @ K @ X, X.T @ F, L @ X)


def first_order_ss(rom):
    fo = rom.to_first_order()
    return np.linalg.solve(fo.E, fo.A), np.linalg.solve(fo.E, fo.B), fo.C


def error_system(fom, rom):
    """Dense (A, B, C) of T - T_r."""
    _, _, sysf = hidden_manifold(fom)
    Ar, Br, Cr = first_order_ss(rom)
    return sla.block_diag(sysf.A, Ar), np.vstack([sysf.B, Br]), np.hstack([sysf.C, -Cr])


def impulse_response(A, B, C, t):
    """C e^{A t_k} B on an equally spaced grid (one matrix exponential): (len(t), p, m)."""
    Phi = sla.expm(A * (t[1] - t[0]))
    X, out = B.copy(), np.empty((t.size, C.shape[0], B.shape[1]))
    for k in range(t.size):
        out[k] = C @ X
        X = Phi @ X
    return out


def rates(errs):
    return np.log2(np.asarray(errs[:-1]) / np.asarray(errs[1:]))


# ---------------------------------------------------------------------------
# full model against the hidden-manifold reference
# ---------------------------------------------------------------------------

CASES = [("dsms", lambda: ms.models.dsms(g=30), 0.4, 120.0),
         ("dsms60", lambda: ms.models.dsms(g=60), 0.4, 120.0),
         ("tcom", lambda: ms.models.tcom(nc=10), 0.04, 12.0),
         ("tcom40", lambda: ms.models.tcom(nc=40), 0.04, 12.0)]


@pytest.mark.parametrize("name,make,h,T", CASES, ids=[c[0] for c in CASES])
def test_step_response_converges_at_order_two(name, make, h, T):
    fom = make()
    _, _, sys = hidden_manifold(fom)
    errs = []
    for k in range(3):
        t = signals.time_grid(T, h / 2 ** k)
        u = signals.step(t, m=fom.m)
        y_ref, _ = reference(sys, t, u)
        errs.append(np.max(np.abs(simulate(fom, t, u) - y_ref)) / np.max(np.abs(y_ref)))
    assert errs[-1] < 1e-3
    np.testing.assert_allclose(rates(errs), 2.0, atol=0.15)


def test_chirp_and_backward_euler_orders():
    fom = ms.models.tcom(nc=10)
    _, _, sys = hidden_manifold(fom)
    T, h = 10.0, 0.02
    tf = signals.time_grid(T, h / 64)  # reference on a fine grid: its own O(h^2) error is 4096x smaller
    sig = dict(omega0=0.2, omega1=3.0, t1=T)
    y_ref, _ = reference(sys, tf, signals.chirp(tf, **sig))
    for scheme, order in (("trapezoidal", 2.0), ("backward-euler", 1.0)):
        errs = []
        for k in range(3):
            t = signals.time_grid(T, h / 2 ** k)
            y = simulate(fom, t, signals.chirp(t, **sig), scheme=scheme)
            errs.append(np.max(np.abs(y - y_ref[:: 64 // 2 ** k])) / np.max(np.abs(y_ref)))
        np.testing.assert_allclose(rates(errs), order, atol=0.15, err_msg=scheme)


def test_impulse_is_the_initial_velocity_equivalent():
    fom = ms.models.dsms(g=30)
    N, (M, _, _, F, _), sys = hidden_manifold(fom)
    k = N.shape[1]
    x0 = np.concatenate([np.zeros(k), np.linalg.solve(M, F[:, 0])])
    errs = []
    for j in range(3):
        t = signals.time_grid(100.0, 0.4 / 2 ** j)
        y, info = simulate(fom, t, signals.impulse(m=1), details=True)
        y_ref, _ = reference(sys, t, np.zeros((t.size, 1)), x0)
        errs.append(np.max(np.abs(y - y_ref)) / np.max(np.abs(y_ref)))
    assert info["lu_count"] == 2 and info["input"] == "impulse"  # S(2/h) and [[M, G^T], [G, 0]]
    np.testing.assert_allclose(rates(errs), 2.0, atol=0.15)


def test_hidden_constraints_and_which_variables_lose_order():
    """x, v and the midpoint multiplier converge at order 2; grid multipliers from an inconsistent
    start do not (the index-3 behaviour), Newmark accelerations need the consistent a_0."""
    fom = ms.models.random_constrained(30, 3, m=1, p=2, seed=4, zeta=0.1, constraints="general")
    N, _, sys = hidden_manifold(fom)
    M, D, K, G, F = (fom.M.toarray(), fom.D.toarray(), fom.K.toarray(), fom.G.toarray(), fom.F[:, 0])
    k, n2 = N.shape[1], fom.n2
    MiGt = np.linalg.solve(M, G.T)
    Z = np.linalg.solve(G @ MiGt, MiGt.T)  # z = (G M^-1 G^T)^-1 G M^-1 (F u - D v - K x)
    S0 = np.block([[M, G.T], [G, np.zeros((n2, n2))]])
    a0z0 = np.linalg.solve(S0, np.concatenate([F, np.zeros(n2)]))  # consistent a(0), z(0) for u(0) = 1
    a0, z0 = a0z0[:-n2], a0z0[-n2:]
    T, h0 = 20.0, 0.05
    out = {"x": [], "v": [], "zmid": [], "zgrid": [], "a": [], "a_incons": []}
    for j in range(3):
        h = h0 / 2 ** j
        t = signals.time_grid(T, h)
        _, info = simulate(fom, t, signals.step(t), details=True, return_state=True)
        x, v, zm = info["x"], info["v"], info["z"]
        np.testing.assert_allclose(info["z_t"], t[:-1] + h / 2)
        # rounding: G x_n at eps, G v_{n+1} = s (G x_{n+1} - G x_n) - G v_n a random walk of s eps
        gx = 10 * EPS * np.abs(G).sum(axis=1).max() * np.max(np.abs(x))
        assert np.max(np.abs(x @ G.T)) <= gx
        assert np.max(np.abs(v @ G.T)) <= gx * 2 / h * np.sqrt(t.size)
        assert np.max(np.abs(np.diff(v, axis=0) @ G.T)) / h <= gx * 4 / h ** 2 * np.sqrt(t.size)
        # the reference on the half grid holds t_n and t_{n+1/2}
        th = signals.time_grid(T, h / 2)
        _, st = reference(sys, th, signals.step(th))
        xr, vr = st[:, :k] @ N.T, st[:, k:] @ N.T
        out["x"].append(np.max(np.abs(x - xr[::2])))
        out["v"].append(np.max(np.abs(v - vr[::2])))
        rest = F - vr @ D.T - xr @ K.T
        zr = rest @ Z.T
        out["zmid"].append(np.max(np.abs(zm - zr[1::2])))
        zg = np.zeros((t.size, n2))  # z_{n+1} = mu_n - z_n from z_0 = 0 (inconsistent: z(0) != 0)
        for n in range(t.size - 1):
            zg[n + 1] = 2 * zm[n] - zg[n]
        out["zgrid"].append(np.max(np.abs(zg - zr[::2])))
        ar = np.linalg.solve(M, (rest - zr @ G)[::2].T).T
        for key, a_start in (("a", a0), ("a_incons", np.zeros(fom.n1))):
            a = np.zeros_like(x)
            a[0] = a_start
            for n in range(t.size - 1):  # Newmark: a_{n+1} = 2/h (v_{n+1} - v_n) - a_n
                a[n + 1] = 2.0 / h * (v[n + 1] - v[n]) - a[n]
            out[key].append(np.max(np.abs(a - ar)))
            if key == "a":  # the recursion sums the rounding of G v, times 2/h, over the steps
                assert np.max(np.abs(a @ G.T)) <= 4 * t.size * 2 / h * np.max(np.abs(v @ G.T)) + 1e-13
    for key in ("x", "v", "zmid", "a"):
        np.testing.assert_allclose(rates(out[key]), 2.0, atol=0.2, err_msg=key)
    for key, size in (("zgrid", np.max(np.abs(z0))), ("a_incons", np.max(np.abs(a0)))):
        assert min(out[key]) > 0.5 * size, key  # no convergence: the start error persists as (-1)^n


# ---------------------------------------------------------------------------
# energy
# ---------------------------------------------------------------------------

def _energy(fom, x, v):
    return 0.5 * np.einsum("ij,ij->i", v, (fom.M @ v.T).T) + 0.5 * np.einsum("ij,ij->i", x, (fom.K @ x.T).T)


def test_undamped_energy_conserved_over_1000_periods():
    base = ms.models.dsms(g=30)
    fom = ms.models.Index3Model(base.M, sp.csr_matrix(base.M.shape), base.K, base.G, base.F, base.L)
    _, (M, _, K, _, _), _ = hidden_manifold(fom)
    w = np.sqrt(sla.eigh(K, M, eigvals_only=True))
    h = 2 * np.pi / w.max() / 10
    t = signals.time_grid(1000 * 2 * np.pi / w.min(), h)
    _, info = simulate(fom, t, signals.impulse(), details=True, return_state=True)
    E = _energy(fom, info["x"], info["v"])
    drift = np.max(np.abs(E - E[0])) / E[0]
    # the trapezoidal rule conserves 1/2 v'Mv + 1/2 x'Kx exactly (G v_bar = 0 removes the
    # multiplier's work): what is left is rounding, a random walk over the steps
    assert drift < 300 * EPS * np.sqrt(t.size), (drift, t.size)  # measured 9.9e-13 over 22221 steps


def test_discrete_energy_balance_with_damping_and_input():
    """E_{n+1} - E_n = -h/4 vb'D vb + h/4 vb'F(u_n + u_{n+1}), vb = v_n + v_{n+1}: exact for the scheme."""
    fom = ms.models.random_constrained(30, 3, m=2, p=2, seed=3, zeta=1e-3)
    t = signals.time_grid(50.0, 0.05)
    u = signals.multisine(t, omegas=[0.3, 1.1], m=2, direction=[1.0, -0.5])
    _, info = simulate(fom, t, u, details=True, return_state=True)
    x, v = info["x"], info["v"]
    E = _energy(fom, x, v)
    vb = v[1:] + v[:-1]
    h = t[1]
    power = -h / 4 * np.einsum("ij,ij->i", vb, (fom.D @ vb.T).T) + h / 4 * np.einsum(
        "ij,ij->i", vb @ fom.F, u[1:] + u[:-1])
    np.testing.assert_allclose(np.diff(E), power, atol=1e-10 * np.max(np.abs(E)))


# ---------------------------------------------------------------------------
# reduced models
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["second-order", "first-order"])
def test_rom_scheme_and_control_agree_to_second_order(kind):
    fom = ms.models.dsms(g=30)
    rom = modal_rom(fom, 6)
    rom = rom if kind == "second-order" else rom.to_first_order()
    diffs = []
    for j in range(3):
        t = signals.time_grid(100.0, 0.5 / 2 ** j)
        u = signals.chirp(t, omega0=0.05, omega1=0.5)
        ys, info_s = simulate(rom, t, u, details=True)
        yc, info_c = simulate(rom, t, u, rom_method="control", details=True)
        diffs.append(np.max(np.abs(ys - yc)) / np.max(np.abs(yc)))
    assert info_s["lu_count"] == 1 and info_c["integrator"].startswith("control")
    assert diffs[-1] < 1e-3
    np.testing.assert_allclose(rates(diffs), 2.0, atol=0.15)
    # the impulse's initial state, through both paths
    t = signals.time_grid(100.0, 0.05)
    yi = simulate(rom, t, signals.impulse())
    np.testing.assert_allclose(yi, simulate(rom, t, signals.impulse(), rom_method="control"),
                               atol=1e-3 * np.max(np.abs(yi)))


def test_rom_scheme_is_the_full_scheme_without_constraints():
    """The dense ROM stepper and the sparse saddle-point stepper are one scheme: a ROM written
    as an unconstrained Index3Model gives the same samples to rounding."""
    fom = ms.models.tcom(nc=10)
    rom = modal_rom(fom, 5)
    as_fom = ms.models.Index3Model(sp.csr_matrix(rom.M), sp.csr_matrix(rom.D), sp.csr_matrix(rom.K), None,
                                   rom.F, rom.L)
    t = signals.time_grid(20.0, 0.05)
    u = signals.step(t)
    for scheme in ("trapezoidal", "backward-euler"):
        y1, y2 = simulate(rom, t, u, scheme=scheme), simulate(as_fom, t, u, scheme=scheme)
        np.testing.assert_allclose(y1, y2, rtol=0, atol=1e-11 * np.max(np.abs(y1)))


def test_fallback_kernel_gives_the_same_samples(monkeypatch):
    """Without the factorized-coordinates view the public SaddleLU.solve path is used."""
    from morsuite.analysis import timestep

    fom = ms.models.random_constrained(25, 2, m=2, p=2, seed=1)
    t = signals.time_grid(5.0, 0.01)
    u = signals.step(t, m=2)
    y1, i1 = simulate(fom, t, u, details=True)
    monkeypatch.setattr(timestep, "_lu_view", lambda f: None)
    y2, i2 = simulate(fom, t, u, details=True)
    assert i1["kernel"] != i2["kernel"] and i1["solves"] == i2["solves"] == t.size
    # the same factors applied two ways: each step's solve differs by the rounding of the equilibrated
    # matrix the LU holds (the trapezoidal rule's s = 2 / h), the steps add it up; measured 9e-15, bound 1.5e-11
    solver = fom.new_solver()
    As = solver._assemble_scaled(*solver._coeffs(i1["s"], None), solver._ordering())[2].toarray()
    assert_rounding(np.abs(y1 - y2).max() / np.abs(y1).max(), i1["steps"] * solve_tolerance(As), "two kernels")


@pytest.mark.parametrize("options", [{"scaling": "ruiz"}, {"scaling": "none"}, {"reuse_ordering": False},
                                     {"backward_tol": 0.0}], ids=["ruiz", "none", "fresh-ordering", "unchecked"])
def test_factorized_coordinates_under_every_scaling_and_ordering(options):
    """Row and column scalings differ under Ruiz; the mapping to the factorized coordinates must
    hold for each equilibration and ordering of the solver."""
    fom = ms.models.random_constrained(30, 3, m=2, p=2, seed=2, mass_spread=3.0, stiffness_spread=3.0)
    t = signals.time_grid(3.0, 0.01)
    u = signals.chirp(t, omega0=0.5, omega1=5.0, m=2, direction=[1.0, 0.3])
    y0 = simulate(fom, t, u)
    y1 = simulate(fom, t, u, solver_options=options)
    np.testing.assert_allclose(y1, y0, rtol=0, atol=1e-10 * np.max(np.abs(y0)))
    with pytest.raises(OptionError, match="solver_options"):
        simulate(fom, t, u, solver_options={"pivoting": 1})


def test_same_scheme_measures_the_reduction_error_better():
    """y - y_r with both on the scheme is close to the exact error; a control ROM adds the
    full model's discretisation error."""
    fom = ms.models.dsms(g=30)
    rom = ms.reducers.make("bt", fom).reduce(8).rom
    Ae, Be, Ce = error_system(fom, rom)
    t = signals.time_grid(200.0, 1.0)
    u = signals.step(t)
    e_exact, _ = reference(control.ss(Ae, Be, Ce, 0), t, u)
    y = simulate(fom, t, u)
    e_scheme = y - simulate(rom, t, u)
    e_mixed = y - simulate(rom, t, u, rom_method="control")
    err_s, err_m = (np.max(np.abs(e - e_exact)) for e in (e_scheme, e_mixed))
    # measured: |e| = 8.5e-6, deviation 2.2e-7 (scheme) and 3.7e-4 (mixed: 40x the error itself)
    assert err_s < 0.05 * np.max(np.abs(e_exact)) < 0.05 * err_m


def _h2(Ae, Be, Ce):
    P = sla.solve_continuous_lyapunov(Ae, -Be @ Be.T)
    return P, float(np.sqrt(np.trace(Ce @ P @ Ce.T)))


def test_h2_bound_siso_is_attained_by_the_reversed_error_impulse_response():
    base = ms.models.dsms(g=30)
    fom = base.with_io(L=base.L[:1])
    rom = modal_rom(fom, 2)
    Ae, Be, Ce = error_system(fom, rom)
    _, h2 = _h2(Ae, Be, Ce)
    t = signals.time_grid(400.0, 0.1)
    he = impulse_response(Ae, Be, Ce, t)[:, 0, 0]
    u = he[::-1] / np.sqrt(np.trapezoid(he ** 2, t))  # ||u||_L2 = 1, worst case for e(T)
    err = output_errors(simulate(fom, t, u), simulate(rom, t, u), t)
    unorm = np.sqrt(np.trapezoid(u ** 2, t))
    assert err["max_output_error"] <= h2 * unorm * (1 + 1e-3)
    assert err["max_output_error"] >= 0.98 * h2 * unorm
    uc = signals.chirp(t, omega0=0.01, omega1=0.6) * np.exp(-t / 100)[:, None]
    err = output_errors(simulate(fom, t, uc), simulate(rom, t, uc), t)
    assert err["max_output_error"] <= h2 * np.sqrt(np.trapezoid(uc[:, 0] ** 2, t))


def test_h2_bound_mimo():
    """MIMO: max_t ||e(t)||_2 <= sqrt(lmax(C P C')) ||u||_L2 <= ||T - T_r||_H2 ||u||_L2; the first is tight."""
    fom = ms.models.random_constrained(40, 2, m=3, p=3, seed=1, zeta=0.2)
    res = ms.reducers.make("bt", fom).reduce(4)
    rom = res.rom
    Ae, Be, Ce = error_system(fom, rom)
    P, h2 = _h2(Ae, Be, Ce)
    lam, W = np.linalg.eigh(Ce @ P @ Ce.T)
    gain = np.sqrt(lam[-1])
    _, (Mh, _, Kh, _, _), _ = hidden_manifold(fom)
    h = 0.05 / np.sqrt(sla.eigh(Kh, Mh, eigvals_only=True).max())
    t = signals.time_grid(150.0, max(h, 0.02))
    win = np.sin(np.pi * t / t[-1]) ** 2
    u = signals.multisine(t, omegas=[0.3, 0.9, 1.7], m=3, direction=[1.0, -1.0, 0.5]) * win[:, None]
    l2 = lambda a: np.sqrt(np.trapezoid(np.sum(a * a, axis=1), t))  # noqa: E731
    err = output_errors(simulate(fom, t, u), simulate(rom, t, u), t)
    assert err["max_output_error"] <= gain * l2(u) <= h2 * l2(u)
    # worst case for the top eigenvector w of C P C': u(tau) = h_e(T - tau)' w
    uw = (W[:, -1] @ impulse_response(Ae, Be, Ce, t))[::-1]
    err = output_errors(simulate(fom, t, uw), simulate(rom, t, uw), t)
    assert err["max_output_error"] >= 0.97 * gain * l2(uw)
    assert err["max_output_error"] <= gain * l2(uw) * (1 + 1e-2)


def test_h2_bound_with_the_exact_error_norm():
    """max_t ||y - y_r||_2 <= ||T - T_r||_H2 ||u||_L2 with ms.analysis.h2_error (no dense model): tight for
    the worst-case input (the reversed error impulse response), far from tight for a chirp. The
    norm itself is checked against the dense Lyapunov value, the reference of the bound."""
    base = ms.models.dsms(g=30)
    fom = base.with_io(L=base.L[:1])
    rom = modal_rom(fom, 2)
    h2, d = ms.analysis.h2_error(fom, rom, details=True)
    assert d["trusted"] and h2 == pytest.approx(_h2(*error_system(fom, rom))[1], rel=1e-8)
    t = signals.time_grid(400.0, 0.1)
    he = impulse_response(*error_system(fom, rom), t)[:, 0, 0]
    l2 = lambda a: float(np.sqrt(np.trapezoid(np.sum(np.reshape(a, (t.size, -1)) ** 2, axis=1), t)))  # noqa: E731
    for u, tight in ((he[::-1] / l2(he), True),
                     (signals.chirp(t, omega0=0.01, omega1=0.6) * np.exp(-t / 100)[:, None], False)):
        err = output_errors(simulate(fom, t, u), simulate(rom, t, u), t)["max_output_error"]
        assert err <= h2 * l2(u) * (1 + 1e-3)   # 1e-3: the scheme's and the quadrature's error
        if tight:
            assert err >= 0.98 * h2 * l2(u)
        else:
            assert err < 0.5 * h2 * l2(u)
    # MIMO (3 inputs, 3 outputs, 2 constraints): the bound with the exact norm
    fom = ms.models.random_constrained(40, 2, m=3, p=3, seed=1, zeta=0.2)
    rom = ms.reducers.make("bt", fom).reduce(4).rom
    h2 = ms.analysis.h2_error(fom, rom)
    t = signals.time_grid(150.0, 0.02)
    u = signals.multisine(t, omegas=[0.3, 0.9, 1.7], m=3, direction=[1.0, -1.0, 0.5]) * \
        (np.sin(np.pi * t / t[-1]) ** 2)[:, None]
    err = output_errors(simulate(fom, t, u), simulate(rom, t, u), t)["max_output_error"]
    assert 0 < err <= h2 * l2(u)


def test_unstable_rom_is_simulated_and_flagged():
    fom = ms.models.dsms(g=30)
    rom = modal_rom(fom, 4)
    bad = ms.rom.SecondOrderROM(rom.M, -0.05 * rom.M, rom.K, rom.F, rom.L)  # negative damping
    t = signals.time_grid(300.0, 0.5)
    for method in ("scheme", "control"):
        with pytest.warns(StabilityWarning, match="right half-plane"):
            y, info = simulate(bad, t, signals.step(t), rom_method=method, details=True)
        assert info["growth"] and info["unstable_poles"] == 2 * 4 and info["growth_factor"] > 10
        assert np.max(np.abs(y[-50:])) > 10 * np.max(np.abs(y[:50]))  # it grows, visibly
    _, info = simulate(rom, t, signals.step(t), details=True)
    assert not info["growth"] and info["unstable_poles"] == 0


# ---------------------------------------------------------------------------
# output errors, options, memory, bad input
# ---------------------------------------------------------------------------

def test_output_errors_planted():
    T = 10.0
    t = signals.time_grid(T, 1e-3)
    y = np.column_stack([np.ones_like(t), np.zeros_like(t)])
    e = np.column_stack([np.sin(t), np.cos(t)])  # ||e(t)||_2 = 1
    out = output_errors(y, y - 0.5 * e, t)
    # the norm of the 2-vectors 0.5 (sin t, cos t): a few operations each, no sum over t (A)
    np.testing.assert_allclose(out["max_output_error"], 0.5, rtol=1e-12)
    np.testing.assert_allclose(out["l2_output_error"], 0.5 * np.sqrt(T), rtol=1e-9)
    np.testing.assert_allclose(out["max_output_rel_error"], 0.5, rtol=1e-12)
    np.testing.assert_allclose(out["l2_output_rel_error"], 0.5, rtol=1e-9)
    ys = np.sin(t)
    out = output_errors(ys, 0.0 * ys, t)  # ||sin||_L2^2 = T/2 - sin(2T)/4
    np.testing.assert_allclose(out["l2_output_error"], np.sqrt(T / 2 - np.sin(2 * T) / 4), rtol=1e-6)
    assert output_errors(0 * ys, 0 * ys, t)["max_output_rel_error"] == 0.0
    assert output_errors(ys, ys + np.inf, t)["max_output_error"] == np.inf
    with pytest.raises(InputError, match="y_r"):
        output_errors(ys, ys[:-1], t)


def test_memory_does_not_grow_with_steps():
    import tracemalloc

    fom = ms.models.dsms(g=3000)
    peaks = {}
    for steps in (200, 2000):
        t = signals.time_grid(steps * 0.5, 0.5)
        u = signals.step(t)
        simulate(fom, t[:3], u[:3])  # warm caches (pattern, imports)
        tracemalloc.start()
        y = simulate(fom, t, u)
        peaks[steps] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    # beyond y and the input (len(t) x (p + 2 m) floats) nothing may scale with the steps
    assert peaks[2000] - peaks[200] < 1800 * (y.shape[1] + 2) * 8 * 2 + 50_000, peaks


def test_options_and_info():
    fom = ms.models.dsms(g=20)
    t = signals.time_grid(5.0, 0.5)
    y, info = simulate(fom, t, np.ones(t.size), details=True)
    assert y.shape == (t.size, 3)
    for key in ("scheme", "rom_method", "return_state", "details", "solver_options"):
        assert key in info["options"]
    assert info["integrator"] == "trapezoidal" and info["lu_count"] == 1 and info["steps"] == 10
    assert info["solves"] == 11 and "x" not in info
    # the fast path reads SaddleLU's fields; a renamed field would fall back (slower) silently
    assert info["kernel"] == "factorized coordinates"
    with pytest.raises(OptionError, match="unknown option 'schem'"):
        simulate(fom, t, np.ones(t.size), schem="trapezoidal")
    with pytest.raises(OptionError, match="scheme"):
        simulate(fom, t, np.ones(t.size), scheme="rk4")
    with pytest.raises(OptionError, match="details=True"):
        simulate(fom, t, np.ones(t.size), return_state=True)
    yc = simulate(fom, t, lambda tk: [1.0])
    np.testing.assert_array_equal(yc, y)


BAD = [
    ("step larger than horizon", lambda fom: simulate(fom, signals.time_grid(1.0, 2.0), 1.0), "larger than the horizon"),
    ("one sample", lambda fom: simulate(fom, [0.0], np.ones(1)), "at least two samples"),
    ("non-uniform t", lambda fom: simulate(fom, [0, 1, 3], np.ones(3)), "equally spaced"),
    ("not from 0", lambda fom: simulate(fom, [1, 2, 3], np.ones(3)), "start at 0"),
    ("decreasing t", lambda fom: simulate(fom, [0, 1, 0.5], np.ones(3)), "strictly increasing"),
    ("nan in t", lambda fom: simulate(fom, [0, np.nan, 2], np.ones(3)), "non-finite"),
    ("nan in u", lambda fom: simulate(fom, [0, 1, 2], [0, np.nan, 1]), r"non-finite samples.*t\[1\]"),
    ("inf in u", lambda fom: simulate(fom, [0, 1, 2], [0, 1, np.inf]), "non-finite"),
    ("channels", lambda fom: simulate(fom, [0, 1, 2], np.ones((3, 2))), "2 channels.*m = 1"),
    ("transposed", lambda fom: simulate(fom.with_io(F=np.ones((fom.n1, 2))), [0, 1, 2], np.ones((2, 3))),
     "transposed"),
    ("length", lambda fom: simulate(fom, [0, 1, 2], np.ones(4)), r"shape \(len\(t\), m\)"),
    ("callable size", lambda fom: simulate(fom, [0, 1, 2], lambda t: [1.0, 2.0]), "returned 2 values"),
    ("impulse channels", lambda fom: simulate(fom, [0, 1, 2], signals.impulse(m=2)), "impulse with 2"),
    ("complex u", lambda fom: simulate(fom, [0, 1, 2], np.ones(3) * 1j), "real"),
    ("not a model", lambda fom: simulate("dsms", [0, 1, 2], np.ones(3)), "system must be"),
]


@pytest.mark.parametrize("case,call,match", BAD, ids=[b[0] for b in BAD])
def test_bad_input_raises_named_error(case, call, match):
    fom = ms.models.dsms(g=10)
    with pytest.raises(InputError, match=match):
        call(fom)


def test_step_equal_to_the_horizon_is_one_step():
    fom = ms.models.dsms(g=10)
    t = signals.time_grid(2.0, 2.0)
    assert t.tolist() == [0.0, 2.0]
    assert simulate(fom, t, np.ones(2)).shape == (2, 3)
