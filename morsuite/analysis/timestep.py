r"""Constant-step implicit time stepping of the constrained model and of dense reduced models.

Full model (:func:`march_index3`)
---------------------------------
The scheme works on the saddle-point system, never on :math:`\Pi`. With
:math:`s = 2/h` (trapezoidal rule) the step from :math:`(x_n, v_n)` is

.. math::

    \begin{bmatrix} s^2 M + s D + K & G^T \\ G & 0 \end{bmatrix}
    \begin{bmatrix} \Delta_n \\ \mu_n \end{bmatrix} =
    \begin{bmatrix} F (u_n + u_{n+1}) + 2 s M v_n - 2 K x_n \\ -G x_n \end{bmatrix},
    \qquad x_{n+1} = x_n + \Delta_n, \quad v_{n+1} = s \Delta_n - v_n,

which is the trapezoidal rule :math:`x_{n+1} - x_n = \tfrac h2 (v_n + v_{n+1})`,
:math:`M (v_{n+1} - v_n) = \tfrac h2 (f_n + f_{n+1})`,
:math:`f = F u - D v - K x - G^T z`, with the constraint :math:`G x_{n+1} = 0` imposed
at every step (the right-hand side :math:`-G x_n` also removes the rounding drift of
:math:`G x_n`), and :math:`\mu_n = z_n + z_{n+1}`. It is Newmark's average
acceleration method (:math:`\beta = 1/4, \gamma = 1/2`) started from the consistent
acceleration, without ever forming an acceleration: no LU of the mass-constraint
matrix is needed for a nonzero :math:`u(0)`. D drops out of the right-hand side.
``scheme="backward-euler"`` (:math:`s = 1/h`): right-hand side
:math:`F u_{n+1} + s M v_n - K x_n`, :math:`v_{n+1} = s \Delta_n`, :math:`\mu_n = z_{n+1}`.

Order. Multiplying the step by a basis N of ker G removes :math:`\mu_n`: the
iterates :math:`x_n = N \hat x_n` are exactly those of the same rule applied to the
hidden-manifold ODE :math:`N^T M N \ddot{\hat x} + \dots = N^T F u`, so x, v and
:math:`y = L x` converge at the order of the rule (2; 1 for backward Euler) and
:math:`G x_n = G v_n = 0` hold to rounding. The multiplier is what loses order:
:math:`\mu_n / 2` is a second-order approximation of :math:`z(t_{n + 1/2})`, but
grid values recovered from :math:`z_{n+1} = \mu_n - z_n` carry any error of
:math:`z_0` undamped, as :math:`(-1)^n` (the index-3 behaviour of the trapezoidal
rule; likewise Newmark accelerations from an inconsistent :math:`a_0`). y does not
depend on z. Modes with :math:`\omega h \gg 1` are not damped by the trapezoidal
rule (:math:`|R(\infty)| = 1`); backward Euler damps them at the price of order 1.

Cost: one sparse LU at :math:`s` (plus one of :math:`[[M, G^T], [G, 0]]` for an
impulse), one checked solve, then per step one stacked sparse product
:math:`\tilde P [\xi; \nu; \bar u]` and one triangular solve. The state is kept in
the coordinates of the factorized (equilibrated, renumbered) matrix so that no
scaling or permutation is applied per step; memory is a few vectors of length
n1 + n2 and the product matrix, independent of the number of steps.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from ..errors import OptionError, SingularShiftError
from ..utils import blas_threads

__all__ = ["SCHEMES", "march_index3", "march_first_order"]

#: scheme -> (s * h, coefficient of K x_n and M v_n in the right-hand side, alpha in v_{n+1} = s Delta - alpha v_n)
SCHEMES = {"trapezoidal": (2.0, 2.0, 1.0), "backward-euler": (1.0, 1.0, 0.0)}


def input_sums(U, scheme):
    """Per-step input term: ``u_n + u_{n+1}`` (trapezoidal) or ``u_{n+1}`` (backward Euler)."""
    return U[:-1] + U[1:] if scheme == "trapezoidal" else U[1:]


def _lu_view(f):
    """(solve, d_row[q], d_col[q], q) of the factorized equilibrated matrix behind a SaddleLU.

    ``SaddleLU`` factors ``(Dr S Dc)[q][:, q]`` (design.md: equilibration, reused
    ordering); solving in those coordinates saves a scaling, two permutations, a
    finiteness and a backward-error pass per step (together 20-60% of a solve on
    dsms(6000), measured). If the fields are not there (another solver layout),
    None: the caller then uses the public ``SaddleLU.solve``.
    """
    try:
        lu, dr, dc, q = f.lu, f.dr, f.dc, f.q
        plain = not f.conjugate and not f.complex_lu and callable(lu.solve)
    except AttributeError:
        return None
    if not plain:
        return None
    N = f.n1 + f.n2
    q = np.arange(N) if q is None else np.asarray(q)
    dr = np.ones(N) if dr is None else np.asarray(dr)
    dc = np.ones(N) if dc is None else np.asarray(dc)
    return lu.solve, dr[q], dc[q], q


def march_index3(fom, t, h, U, *, scheme="trapezoidal", impulse=None, return_state=False, solver_options=None):
    r"""Step the full model over the grid ``t``; returns ``(Y, info)``.

    Parameters
    ----------
    fom : Index3Model
    t, h : time grid from 0 and its step
    U : ndarray (len(t), m), the input samples
    impulse : ndarray (m,), optional
        Direction b of a unit impulse at t = 0: start from x = 0 and the velocity
        :math:`v_0` of :math:`[[M, G^T], [G, 0]] [v_0; \nu] = [F b; 0]` (one more LU), with
        zero input (U must then be zero).
    return_state : bool
        Also return ``x``, ``v`` (len(t), n1) and the multiplier estimates in ``info``.
    solver_options : dict, optional
        Passed to ``fom.new_solver``.
    """
    sh, ck, alpha = SCHEMES[scheme]
    s = sh / h
    n1, n2, nt = fom.n1, fom.n2, len(t)
    N = n1 + n2
    t0 = time.perf_counter()
    try:
        solver = fom.new_solver(**{"cache_size": 0, **(solver_options or {})})
    except TypeError as exc:  # an unknown keyword of SaddlePointSolver
        raise OptionError(f"solver_options {solver_options!r} are not options of the saddle-point solver: "
                          f"{exc}") from exc
    f = solver.factor(s)
    # one checked solve: a failed backward-error check refactors with a safer pivoting here,
    # before the unchecked per-step solves start
    f.solve(np.vstack([np.abs(fom.F).sum(axis=1, keepdims=True), np.zeros((n2, 1))]), full=True)
    view = _lu_view(f)
    fast = view is not None
    if not fast:
        view = (lambda b: f.solve(b, full=True), np.ones(N), np.ones(N), np.arange(N))
    solve, drq, dcq, q = view
    qinv = np.empty_like(q)
    qinv[q] = np.arange(N)

    P = _step_operator(fom, s, ck, drq, dcq, q)

    w = np.zeros(2 * N + fom.m)
    xi, nu, ub = w[:N], w[N:2 * N], w[2 * N:]
    if impulse is not None:
        v0 = solver.factor(coeffs=(1.0, 0.0, 0.0)).solve(fom.F @ impulse)
        vf = np.concatenate([v0, np.zeros(n2)])
        nu[:] = vf[q] / (s * dcq)
    Ubar = input_sums(U, scheme)
    Y = np.zeros((nt, fom.p))
    state = None
    if return_state:
        state = {"x": np.zeros((nt, n1)), "v": np.zeros((nt, n1)), "z": np.zeros((nt - 1, n2))}
        state["v"][0] = (s * dcq * nu)[qinv][:n1]
    t1 = time.perf_counter()
    with blas_threads(1):
        for n in range(nt - 1):
            ub[:] = Ubar[n]
            r = P @ w
            Y[n] = r[N:]
            y = solve(r[:N])
            xi += y
            if alpha:
                np.subtract(y, nu, out=nu)
            else:
                nu[:] = y
            if state is not None:
                state["x"][n + 1] = (dcq * xi)[qinv][:n1]
                state["v"][n + 1] = (s * dcq * nu)[qinv][:n1]
                state["z"][n] = (dcq * y)[qinv][n1:] / (2.0 if alpha else 1.0)
        Y[nt - 1] = (P @ w)[N:]
    t2 = time.perf_counter()
    x_end, v_end = (dcq * xi)[qinv][:n1], (s * dcq * nu)[qinv][:n1]
    st = solver.stats
    info = {"s": s, "lu_count": st.factorizations, "solves": st.solves + (nt - 1 if fast else 0),
            "kernel": "factorized coordinates" if fast else "SaddleLU.solve",
            "lu_nnz": getattr(getattr(f, "lu", None), "nnz", None),
            "factor_time_s": st.factor_time_s + st.assemble_time_s, "march_time_s": t2 - t1,
            "setup_time_s": t1 - t0, "constraint_residual": _constraint_residual(fom.G, x_end, v_end, s)}
    if state is not None:
        info.update(state)
        info["z_t"] = t[:-1] + h / 2 if alpha else t[1:]
    return Y, info


def _step_operator(fom, s, ck, drq, dcq, q):
    """The stacked sparse matrix of one step in the factorized coordinates, shape (N + p, 2N + m).

    Rows :N give the right-hand side ``b = Ax x + Av v + [F; 0] ubar`` with
    ``Ax = [[-ck K], [-G]]``, ``Av = [[ck s M], [0]]``, mapped by ``x_full[q] = dcq * xi``,
    ``v_full[q] = s * dcq * nu``, ``b_lu = drq * b[q]``; rows N: give ``y = L x`` of the
    current state, so that one product per step serves the solve and the output.
    """
    n1, n2, p, m = fom.n1, fom.n2, fom.p, fom.m
    N = n1 + n2
    Ax = sp.bmat([[-ck * fom.K, sp.csr_matrix((n1, n2))], [-fom.G, sp.csr_matrix((n2, n2))]], format="csr")
    Av = sp.bmat([[(ck * s) * fom.M, sp.csr_matrix((n1, n2))], [sp.csr_matrix((n2, n1)), sp.csr_matrix((n2, n2))]],
                 format="csr")
    Ff = np.vstack([fom.F, np.zeros((n2, m))])
    Lf = np.hstack([fom.L, np.zeros((p, n2))])[:, q] * dcq
    Dr, Dc = sp.diags(drq), sp.diags(dcq)
    P = sp.bmat([[Dr @ Ax[q][:, q] @ Dc, Dr @ Av[q][:, q] @ (s * Dc), sp.csr_matrix(drq[:, None] * Ff[q])],
                 [sp.csr_matrix(Lf), sp.csr_matrix((p, N)), sp.csr_matrix((p, m))]], format="csr")
    P.eliminate_zeros()
    return P


def _constraint_residual(G, x, v, s) -> dict:
    """At the last step: |G x|_inf / (||G||_inf ||x||_inf) and |G v|_inf / (||G||_inf (||v||_inf + s ||x||_inf)).

    v is scaled with s ||x|| as well: v_{n+1} = s Delta_n - v_n carries the rounding of
    x times s, and near a steady state v itself is at rounding level. 0 where x and v vanish.
    """
    if G.shape[0] == 0:
        return {"Gx": 0.0, "Gv": 0.0}
    g = float(abs(G).sum(axis=1).max())
    xn, vn = float(np.max(np.abs(x))), float(np.max(np.abs(v)))
    out = {}
    for k, vec, den in (("Gx", x, g * xn), ("Gv", v, g * (vn + s * xn))):
        out[k] = float(np.max(np.abs(G @ vec)) / den) if den > 0 else 0.0
    return out


def march_first_order(E, A, B, C, D, t, h, U, *, scheme="trapezoidal", w0=None, return_state=False):
    r"""The same rule on a dense descriptor model :math:`E \dot w = A w + B u`, :math:`y = C w + D u`.

    Trapezoidal: :math:`(sE - A)\Delta_n = 2 A w_n + B (u_n + u_{n+1})`, :math:`s = 2/h`;
    backward Euler: :math:`(sE - A)\Delta_n = A w_n + B u_{n+1}`, :math:`s = 1/h`;
    :math:`w_{n+1} = w_n + \Delta_n`. For :math:`E = \mathrm{blkdiag}(I, \hat M)`,
    :math:`A = [[0, I], [-\hat K, -\hat D]]` this is the full model's step without
    constraint. One dense LU of :math:`sE - A`; the one-step map
    :math:`w_{n+1} = \Phi w_n + Q \bar u_n` is formed once from it.
    """
    sh, ck, _ = SCHEMES[scheme]
    s = sh / h
    k = A.shape[0]
    S = s * E - A
    lu, piv = sla.lu_factor(S, check_finite=True)
    dg = np.abs(np.diag(lu))
    if not np.all(dg > np.finfo(float).eps * max(np.max(np.abs(S)), 1e-300) * k):
        raise SingularShiftError(
            f"the step matrix sE - A of the reduced model is singular at s = {s:g} (step h = {h:g}): "
            "s is a pole of the model; choose another step")
    Phi = np.eye(k) + sla.lu_solve((lu, piv), ck * A)
    Q = sla.lu_solve((lu, piv), B)
    Ubar = input_sums(U, scheme)
    nt = len(t)
    W = np.zeros((nt, k))
    if w0 is not None:
        W[0] = w0
    QU = Ubar @ Q.T
    with blas_threads(1):
        for n in range(nt - 1):
            W[n + 1] = Phi @ W[n] + QU[n]
    Y = W @ C.T + U @ D.T
    info = {"s": s, "lu_count": 1, "solves": B.shape[1] + k}
    if return_state:
        info["w"] = W
    return Y, info
