r"""First-order tangential IRKA against a dense modal surrogate, and Newton on its fixed-point map.

The first-order IRKA (:mod:`morsuite.reducers.irka.first_order`) maps interpolation data
:math:`x = (\sigma_i, b_i, c_i)` to the mirrored poles and residue directions
of the reduced model that interpolates at :math:`x`; its fixed points are the
stationary points of the H2 error (Meier-Luenberger conditions). On a lightly
damped model with many resonances the plain iteration :math:`x \leftarrow f(x)`
need not converge: on ``tcom(nc=200)`` at 40 states it settles into a 2-cycle
next to fixed points whose Jacobian :math:`f'` has eigenvalues of modulus 2
(``docs/design/irka_fo.md``). Newton's method on :math:`F(x) = f(x) - x` converges
there, but needs :math:`f'`, i.e. one map evaluation per real parameter. Against the
full model each evaluation is a round of sparse LUs; against a surrogate it is dense
work on small matrices.

The surrogate (:class:`ModalSurrogate`) is a first-order balanced truncation
:math:`T_s(s) = C_s(sI - A_s)^{-1}B_s` of N states from the model's cached Gramian
factors, in modal form :math:`T_s(s) = \sum_n C_{s,n}B_{s,n}^T/(s - \mu_n)`. Then

- the interpolant at :math:`x` (:meth:`ModalSurrogate.interpolant`): with
  :math:`v_i = (\sigma_i - \mu)^{-1}\circ B_sb_i`, :math:`w_i = (\sigma_i - \mu)^{-1}\circ C_s^Tc_i`,
  :math:`E_r = W^TV`, :math:`A_r = W^T\mathrm{diag}(\mu)V`, :math:`B_r = W^TB_s`,
  :math:`C_r = C_sV`, turned real by the congruence that maps a conjugate pair of
  columns to their real and imaginary parts: :math:`O(Nk(k + m + p))` flops;
- its H2 error against the surrogate (:meth:`ModalSurrogate.error_squared`): the
  pole-residue formula of :mod:`morsuite.linalg.h2` with
  :math:`T_s(-\lambda_k)b_k` in :math:`O(N(m+p))` per pole.

Coordinates (:class:`Chart`): one slot per real shift or conjugate pair; a slot holds
its shift (real, or real and imaginary part) and its directions divided by their
pivot entry (the entry of largest modulus at the reference point), whose other entries
are the free coordinates (directions are defined up to a complex factor).

Cost: everything here is dense; no sparse LU.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from ...linalg.dense import shift_distance
from ...linalg.h2 import Modal, modal_form, pole_residue_squared
from ...rom import FirstOrderROM
from .jacobian import map_jacobian
from .shift_update import COMPLEX_TOL, relaxed_update, shifts_from_poles

__all__ = ["ModalSurrogate", "Chart", "SurrogateMap", "NewtonResult", "newton_fixed_point", "fixed_point_jacobian",
           "iterate"]


class ModalSurrogate:
    """A real first-order model :math:`(E, A, B, C)` (E nonsingular) held in modal form.

    Attributes: ``mu`` (N poles), ``B`` (N x m), ``C`` (p x N), ``kappa`` (condition of the
    normalised eigenvector matrix), ``norm2`` (:math:`\\|T_s\\|_{\\mathcal H_2}^2`), ``states``.
    """

    def __init__(self, rom):
        E = np.asarray(rom.E)
        if np.array_equal(E, np.eye(E.shape[0])):
            # a balanced realization (E = I): the standard eigenproblem, no QZ
            lam, X = np.linalg.eig(rom.A)
            Xn = X / np.linalg.norm(X, axis=0)
            with np.errstate(all="ignore"):
                kappa = float(np.linalg.cond(Xn))
            m = Modal(lam, rom.C @ Xn, np.linalg.solve(Xn, rom.B), np.asarray(rom.D, dtype=float),
                      kappa if np.isfinite(kappa) else np.inf)
        else:
            m = modal_form(rom.E, rom.A, rom.B, rom.C, rom.D)
        self.mu, self.B, self.C, self.kappa = m.poles, m.B, m.C, m.kappa
        self.norm2 = m.self_inner()[0]
        self.states = int(rom.states)

    def interpolant(self, alpha, bdir, cdir) -> FirstOrderROM:
        """The real reduced model interpolating the surrogate at (alpha, b, c), tangentially and
        Hermite: alpha closed under conjugation, a pair's directions conjugate."""
        R = 1.0 / (alpha[None, :] - self.mu[:, None])
        V = (self.B @ bdir.T) * R
        W = (self.C.T @ cdir.T) * R
        Q = _real_basis(alpha)
        Er = Q.T @ (W.T @ V) @ Q
        Ar = Q.T @ (W.T @ (self.mu[:, None] * V)) @ Q
        Br = Q.T @ (W.T @ self.B)
        Cr = (self.C @ V) @ Q
        # in modal coordinates a real vector's entries come in conjugate pairs, so these are
        # real up to rounding
        return FirstOrderROM(Er.real, Ar.real, Br.real, Cr.real)

    def error_squared(self, modal) -> float:
        r""":math:`\|T_s - T_r\|_{\mathcal H_2}^2` of a reduced model in modal form (``linalg.h2.Modal``)."""
        G = (self.B @ modal.B.T) / (-modal.poles[None, :] - self.mu[:, None])
        terms = np.sum(modal.C * (self.C @ G), axis=0)
        e2, _, _ = pole_residue_squared(self.norm2, 0.0, complex(np.sum(terms)), float(np.sum(np.abs(terms))), modal)
        return e2


def _real_basis(alpha):
    """Q with V Q = [.., v_i, .., Re v_j, Im v_j, ..]: a real shift's column kept, a conjugate
    pair's two columns (j, j') mapped to their real and imaginary parts."""
    k = alpha.size
    Q = np.zeros((k, k), dtype=complex)
    cplx = np.abs(alpha.imag) > COMPLEX_TOL * np.abs(alpha)
    done = np.zeros(k, bool)
    where = {}
    for t, a in enumerate(alpha.tolist()):
        where.setdefault(complex(a), []).append(t)
    for i in range(k):
        if done[i]:
            continue
        if not cplx[i]:
            Q[i, i] = 1.0
            done[i] = True
            continue
        j = next((t for t in where.get(complex(np.conj(alpha[i])), ()) if not done[t] and t != i), None)
        if j is None:  # no exact conjugate: the nearest one
            cand = np.flatnonzero(~done & cplx & (np.arange(k) != i))
            j = cand[np.argmin(np.abs(alpha[cand] - np.conj(alpha[i])))]
        Q[i, i], Q[j, i] = 0.5, 0.5
        Q[i, j], Q[j, j] = -0.5j, 0.5j
        done[[i, j]] = True
    return Q


@dataclass
class Chart:
    """Real coordinates of interpolation data near a reference point (see the module docstring).

    ``shifts``: the reference shift of each slot (real ones first, then the upper members
    of the pairs); ``jb``, ``jc``: the pivot entry of each slot's directions.
    """

    shifts: np.ndarray
    jb: np.ndarray
    jc: np.ndarray
    m: int
    p: int
    n_real: int = field(init=False)

    def __post_init__(self):
        self.n_real = int(np.sum(self.shifts.imag == 0))

    @classmethod
    def at(cls, alpha, bdir, cdir):
        """The chart at interpolation data (alpha, b, c); None if alpha is not closed under conjugation."""
        sel = _slots(alpha)
        if sel is None:
            return None
        a = alpha[sel].copy()
        real = np.abs(a.imag) <= COMPLEX_TOL * np.abs(a)
        a[real] = a[real].real
        return cls(a, np.argmax(np.abs(bdir[sel]), axis=1), np.argmax(np.abs(cdir[sel]), axis=1),
                   bdir.shape[1], cdir.shape[1])

    @property
    def size(self) -> int:
        """Number of real coordinates of the chart: per real shift 1 + (m - 1) + (p - 1) (the shift and
        the normalised directions), per complex pair twice that."""
        nr, nc = self.n_real, self.shifts.size - self.n_real
        return nr * (1 + (self.m - 1) + (self.p - 1)) + 2 * nc * (1 + (self.m - 1) + (self.p - 1))

    def encode(self, alpha, bdir, cdir):
        """x for data (alpha, b, c) whose slots match this chart's (assignment to the reference
        shifts); None if they do not split alike into real shifts and pairs."""
        sel = _slots(alpha)
        if sel is None or sel.size != self.shifts.size:
            return None
        a, b, c = alpha[sel], bdir[sel], cdir[sel]
        real = np.abs(a.imag) <= COMPLEX_TOL * np.abs(a)
        if int(real.sum()) != self.n_real:
            return None
        order = np.empty(sel.size, dtype=int)
        for mask, ref in ((real, slice(0, self.n_real)), (~real, slice(self.n_real, None))):
            idx = np.flatnonzero(mask)
            rs = self.shifts[ref]
            if idx.size:
                i, j = linear_sum_assignment(np.abs(a[idx][:, None] - rs[None, :]) / np.abs(rs)[None, :])
                order[np.arange(sel.size)[ref][j]] = idx[i]
        a, b, c = a[order], b[order], c[order]
        rows = np.arange(a.size)
        b = b / b[rows, self.jb][:, None]
        c = c / c[rows, self.jc][:, None]
        keep_b, keep_c = self._masks()
        v = np.concatenate([a[:, None], b[keep_b].reshape(a.size, self.m - 1),
                            c[keep_c].reshape(a.size, self.p - 1)], axis=1)
        nr = self.n_real
        return np.concatenate([v[:nr].real.ravel(), np.concatenate([v[nr:].real, v[nr:].imag], axis=1).ravel()])

    def _masks(self):
        """Boolean masks of the free (non-pivot) entries of each slot's b and c."""
        S = self.shifts.size
        keep_b, keep_c = np.ones((S, self.m), bool), np.ones((S, self.p), bool)
        keep_b[np.arange(S), self.jb] = False
        keep_c[np.arange(S), self.jc] = False
        return keep_b, keep_c

    def decode(self, x):
        """(alpha, b, c), closed under conjugation, of coordinates x (a real slot's entries, then
        each pair's upper member followed by its conjugate)."""
        S, nr = self.shifts.size, self.n_real
        nfree = 1 + (self.m - 1) + (self.p - 1)
        xr = x[:nr * nfree].reshape(nr, nfree)
        xc = x[nr * nfree:].reshape(S - nr, 2, nfree)
        v = np.concatenate([xr.astype(complex), xc[:, 0] + 1j * xc[:, 1]])
        keep_b, keep_c = self._masks()
        b = np.ones((S, self.m), dtype=complex)
        c = np.ones((S, self.p), dtype=complex)
        b[keep_b] = v[:, 1:self.m].ravel()
        c[keep_c] = v[:, self.m:].ravel()
        # output order: real slots, then each pair's upper member and its conjugate
        idx = np.concatenate([np.arange(nr), np.repeat(np.arange(nr, S), 2)])
        conj = np.concatenate([np.zeros(nr, bool), np.tile([False, True], S - nr)])
        al, b, c = v[idx, 0], b[idx], c[idx]
        al[conj], b[conj], c[conj] = al[conj].conj(), b[conj].conj(), c[conj].conj()
        return al, b, c

    def scales(self, x):
        """Per coordinate: ``|shift|`` for a slot's shift coordinates, 1 for direction coordinates."""
        S, nr = self.shifts.size, self.n_real
        nfree = 1 + (self.m - 1) + (self.p - 1)
        mag = np.abs(self.shifts)
        r = np.ones((nr, nfree))
        r[:, 0] = mag[:nr]
        c = np.ones((S - nr, 2, nfree))
        c[:, :, 0] = mag[nr:, None]
        return np.concatenate([r.ravel(), c.ravel()]).astype(x.dtype, copy=False)


def _slots(alpha):
    """Indices of the real shifts and of the upper members of conjugate pairs, or None when
    alpha is not closed under conjugation."""
    cplx = np.abs(alpha.imag) > COMPLEX_TOL * np.abs(alpha)
    up, down = np.flatnonzero(cplx & (alpha.imag > 0)), np.flatnonzero(cplx & (alpha.imag < 0))
    if up.size != down.size:
        return None
    return np.concatenate([np.flatnonzero(~cplx), up])


class SurrogateMap:
    """The first-order IRKA map against a :class:`ModalSurrogate`, with H2 errors and evaluation counts."""

    def __init__(self, surrogate: ModalSurrogate, band, analytic: bool = True):
        self.s = surrogate
        self.band = band
        self.evaluations = 0
        self.analytic = analytic  # closed-form Jacobian where it applies
        self.analytic_jacobians = 0

    def step(self, alpha, bdir, cdir):
        """(rom, modal, e2, (alpha', b', c')): the interpolant at (alpha, b, c), its modal form,
        its squared H2 error against the surrogate, and its mirrored poles with unit residue
        directions. e2 is inf for an unstable or defective interpolant."""
        self.evaluations += 1
        rom = self.s.interpolant(alpha, bdir, cdir)
        if not np.linalg.cond(rom.E) < 1e12:
            # more shifts than the surrogate's numerical order (the DSMS beyond about 20 states): the
            # full model's iteration caps the order; the surrogate's is not meant to
            raise ArithmeticError(f"the surrogate's interpolant at {alpha.size} shifts has a singular E")
        modal = modal_form(rom.E, rom.A, rom.B, rom.C, rom.D)
        lam = modal.poles
        ok = np.isfinite(modal.kappa) and np.all(lam.real < 0)
        e2 = self.s.error_squared(modal) if ok else np.inf
        nxt = shifts_from_poles(lam.copy(), modal.B, modal.C.T, self.band)[:3]
        return rom, modal, e2, nxt

    def residual(self, chart: Chart, x):
        """F(x) = chart(f(decode(x))) - x, scaled per coordinate (None where the chart breaks)."""
        alpha, b, c = chart.decode(x)
        if np.any(alpha.real <= 0):
            return None
        try:
            _, _, e2, nxt = self.step(alpha, b, c)
        except (np.linalg.LinAlgError, ValueError, ArithmeticError):  # InputError is a ValueError
            return None
        y = chart.encode(*nxt)
        return None if y is None else (y - x, e2)


@dataclass
class NewtonResult:
    """Outcome of :func:`newton_fixed_point`."""

    converged: bool
    data: tuple          # (alpha, b, c) at the last point
    e2: float            # surrogate H2 error squared of the interpolant there
    steps: int
    residual: float      # largest scaled |F| at the last point
    jacobian: np.ndarray | None = None   # f'(x) at the last point, chart coordinates
    chart: Chart | None = None
    history: list = field(default_factory=list)


def newton_fixed_point(smap: SurrogateMap, alpha, bdir, cdir, *, tol=1e-10, maxit=40, fd_step=1e-7,
                       stall_tol=None) -> NewtonResult:
    r"""Newton's method on :math:`F(x) = f(x) - x` for the surrogate's IRKA map.

    The Jacobian :math:`f'` is the closed form of :func:`~morsuite.reducers.irka.jacobian.map_jacobian` where it
    applies, else forward differences (one map evaluation per real coordinate, steps ``fd_step``
    times the coordinate's scale); each Newton step
    :math:`\Delta = -(f' - I)^{-1}F` is backtracked (halving, at most 6 times) until the
    scaled :math:`\|F\|` decreases. Stops when the largest scaled :math:`|F_j|` (relative
    shift change, direction change) is below ``tol``; a point where the steps stop reducing it
    counts as a fixed point when it is below ``stall_tol`` (default ``100 tol``: the map's
    rounding; the surrogate phase passes ten times its iteration's tolerance, as tcom(nc=2000)
    at 44 states stalls at 1.4e-8).

    Cost per step: one Jacobian (closed form: about one map evaluation; differences:
    coordinates + 1 evaluations) and the backtracking's map evaluations, each
    :math:`O(Nk(k+m+p) + k^3)` dense flops; no sparse LU.
    """
    chart = Chart.at(alpha, bdir, cdir)
    if chart is None:
        return NewtonResult(False, (alpha, bdir, cdir), np.inf, 0, np.inf)
    x = chart.encode(alpha, bdir, cdir)
    sc = chart.scales(x)
    out = smap.residual(chart, x)
    hist = []
    if out is None:
        return NewtonResult(False, (alpha, bdir, cdir), np.inf, 0, np.inf, chart=chart)
    F, e2 = out
    Jf, Jf_at_x = None, False
    mu0 = 1e-4
    stall = 100 * tol if stall_tol is None else stall_tol
    for step in range(maxit + 1):
        res = float(np.max(np.abs(F) / sc)) if F.size else 0.0
        hist.append({"residual": res, "e2": float(e2)})
        if res < tol:
            Jf = _jacobian(smap, chart, x, F, sc, fd_step)
            return NewtonResult(True, chart.decode(x), e2, step, res, Jf, chart, hist)
        if step == maxit:
            break
        Jf = _jacobian(smap, chart, x, F, sc, fd_step)
        Jf_at_x = True
        if Jf is None:
            break
        # Levenberg-Marquardt on ||F||^2 in scaled coordinates: the Newton step first (mu = 0),
        # then steps bent towards the gradient until the scaled residual decreases
        Ms = (Jf - np.eye(x.size)) / sc[:, None] * sc[None, :]
        Fs = F / sc
        norm0 = np.linalg.norm(Fs)
        H, g = Ms.T @ Ms, Ms.T @ Fs
        dH = np.maximum(np.diag(H), np.finfo(float).tiny)
        accepted = None
        for mu in [0.0] + [mu0 * 10.0 ** k for k in range(9)]:
            try:
                dxs = (np.linalg.solve(Ms, -Fs) if mu == 0 else np.linalg.solve(H + mu * np.diag(dH), -g))
            except np.linalg.LinAlgError:
                continue
            trial = smap.residual(chart, x + dxs * sc)
            if trial is not None and np.linalg.norm(trial[0] / sc) < (1.0 - 1e-4) * norm0:
                accepted = (x + dxs * sc, trial)
                mu0 = max(mu / 10.0, 1e-8) if mu else mu0
                break
            if mu == 0 and res < stall:
                break  # the Newton step fails at the map's rounding floor: no bent steps (each costs an evaluation)
        if accepted is None:
            break
        x, (F, e2) = accepted[0], accepted[1]
        Jf_at_x = False
    res = hist[-1]["residual"]
    if res < stall:
        # stalled at the rounding level of the map (ill-conditioned modal forms): a fixed point all the same
        if not (Jf_at_x and Jf is not None):
            Jf = _jacobian(smap, chart, x, F, sc, fd_step)
        return NewtonResult(Jf is not None, chart.decode(x), e2, step, res, Jf, chart, hist)
    return NewtonResult(False, chart.decode(x), e2, step, res, Jf, chart, hist)


def fixed_point_jacobian(smap: SurrogateMap, alpha, bdir, cdir, fd_step=1e-7):
    """(chart, f'(x)) at data (alpha, b, c): the chart there and the forward-difference Jacobian of
    the map in its coordinates (None where the chart breaks). Cost: coordinates + 1 map evaluations."""
    chart = Chart.at(alpha, bdir, cdir)
    if chart is None:
        return None, None
    x = chart.encode(alpha, bdir, cdir)
    out = smap.residual(chart, x)
    if out is None:
        return chart, None
    return chart, _jacobian(smap, chart, x, out[0], chart.scales(x), fd_step)


def _jacobian(smap, chart, x, F, sc, h):
    """f'(x) in chart coordinates: in closed form (:func:`~morsuite.reducers.irka.jacobian.map_jacobian`), else
    (where that does not apply) by forward differences; None if a perturbed point breaks the chart."""
    if smap.analytic:
        J = map_jacobian(smap.s.mu, smap.s.B, smap.s.C, chart, x, F + x)
        if J is not None:
            smap.analytic_jacobians += 1
            return J
    n = x.size
    J = np.empty((n, n))
    fx = F + x
    for j in range(n):
        d = h * max(abs(x[j]), sc[j])
        xp = x.copy()
        xp[j] += d
        out = smap.residual(chart, xp)
        if out is None:
            return None
        J[:, j] = (out[0] + xp - fx) / d
    return J


def iterate(smap: SurrogateMap, alpha, bdir, cdir, *, maxit=300, tol=1e-10, plain=50, relaxation=0.5,
            keep=4, stop_below=0.0, start=0, best=None, stall=0):
    """IRKA against the surrogate: plain steps x <- f(x), then (no convergence after ``plain``
    steps) relaxed ones, each shift moved the fraction ``relaxation`` towards its matched new value
    (:func:`~morsuite.reducers.irka.shift_update.relaxed_update`), until the matched relative shift change is below ``tol``.

    ``stop_below`` > 0: stop early (``stopped_early`` True) once the shift change is below it and
    has decreased over the last three steps (a contracting iteration near a fixed point: Newton's
    method finishes faster); ``start`` and ``best`` resume such a run (iterations counted on).
    ``stall`` > 0: stop (``stalled`` True) when the shift change has not come below half its
    smallest value within the last ``stall`` steps (a map whose rounding floor lies above
    ``tol``: measured on dsms(g=1000) at 12 states, where it hovers at 3e-7 to 4e-6).

    Returns a dict: ``converged``, ``iterations``, ``relaxed_from`` (the first relaxed step or None),
    ``measure`` (the last shift change), ``last`` (the data of the last step), ``stopped_early``,
    ``stalled`` and
    ``best``: up to ``keep`` distinct iterates of smallest surrogate H2 error as
    (e2, iteration, (alpha, b, c)), the data each interpolant was built at.
    """
    best = [] if best is None else best
    w, relaxed_from, d = 1.0, None, np.inf
    if start >= plain:
        w, relaxed_from = relaxation, start + 1
    it, trail, low, low_at = start, [], np.inf, start
    for it in range(start + 1, maxit + 1):
        _, _, e2, nxt = smap.step(alpha, bdir, cdir)
        d = shift_distance(nxt[0], alpha)
        _keep_best(best, (e2, it, (alpha, bdir, cdir)), keep)
        if d < tol and np.isfinite(e2):
            return {"converged": True, "iterations": it, "relaxed_from": relaxed_from, "measure": d,
                    "last": (alpha, bdir, cdir), "best": best, "stopped_early": False, "stalled": False}
        if d < 0.5 * low:
            low, low_at = d, it
        elif stall > 0 and it - low_at >= stall:
            return {"converged": False, "iterations": it, "relaxed_from": relaxed_from, "measure": d,
                    "last": (alpha, bdir, cdir), "best": best, "stopped_early": False, "stalled": True}
        trail = (trail + [d])[-4:]
        if (stop_below > 0 and d < stop_below and np.isfinite(e2) and len(trail) == 4
                and trail[0] > trail[1] > trail[2] > trail[3]):
            return {"converged": False, "iterations": it, "relaxed_from": relaxed_from, "measure": d,
                    "last": (alpha, bdir, cdir), "best": best, "stopped_early": True, "stalled": False}
        if it == plain and w == 1.0:
            # the plain iteration has not converged: damp it (a fixed point whose map has an eigenvalue
            # below -1, e.g. -1.56 on tcom(nc=200) at 40 states, is reached with w < 2 / (1 + 1.56))
            w, relaxed_from = relaxation, it + 1
        alpha, bdir, cdir = relaxed_update(alpha, bdir, cdir, *nxt, w) if w < 1.0 else nxt
    return {"converged": False, "iterations": it, "relaxed_from": relaxed_from, "measure": d,
            "last": (alpha, bdir, cdir), "best": best, "stopped_early": False, "stalled": False}


def _keep_best(best, item, keep):
    """Insert item into the list of the ``keep`` smallest-e2 iterates whose shift sets differ
    by more than 1e-3 (a near-repeat replaces its twin if it is better)."""
    e2, _, (alpha, _, _) = item
    if not np.isfinite(e2):
        return
    for i, (e2o, _, (ao, _, _)) in enumerate(best):
        if ao.size == alpha.size and shift_distance(alpha, ao) < 1e-3:
            if e2 < e2o:
                best[i] = item
                best.sort(key=lambda t: t[0])
            return
    best.append(item)
    best.sort(key=lambda t: t[0])
    del best[keep:]
