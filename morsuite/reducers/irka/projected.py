r"""The explicit :math:`\Pi`-projected dense IRKA: the baseline the paper avoids.

The index-3 system is turned into a standard second-order system the way the
paper's Section 2.2 describes it, with every matrix the paper calls
"forbidden" for large systems actually formed, and the structure-preserving
IRKA of the paper's Algorithm 1 (SPIRKA) is run on it with dense solves.
Its purpose is to measure that cost honestly, against the projector-free
Algorithm 2 (reducer ``"irka"``), from the same shifts.

Steps (done once per reducer, reused for every ``r``)
------------------------------------------------------
1. **Form** :math:`\Pi = I - G^T (G M^{-1} G^T)^{-1} G M^{-1}` (paper's
   eq. ``indexred:piprojetor``) as a dense :math:`n_1 \times n_1` array
   (one sparse LU of :math:`M` for :math:`G M^{-1}`).
2. **Split** :math:`\Pi = \Psi_l \Psi_r^T`, :math:`\Psi_l^T \Psi_r = I_{n_1-n_2}`
   (eq. ``indexred:projectionproperty``; the paper prints
   :math:`\Pi = \Psi_l\Psi_r`, a dimension typo). Choice made here:
   :math:`\Psi_r` is an *orthonormal* basis of
   :math:`\mathrm{range}(\Pi^T) = \mathrm{null}(G)`, computed by a
   rank-revealing (column-pivoted) Householder QR of the explicit
   :math:`\Pi^T` (LAPACK ``geqp3`` + ``orgqr``, in place), and
   :math:`\Psi_l = \Pi \Psi_r`. Then :math:`\Psi_l \Psi_r^T = \Pi\,\Psi_r\Psi_r^T = \Pi`
   (:math:`\Psi_r\Psi_r^T` is the orthogonal projector onto
   :math:`\mathrm{range}(\Pi^T)`) and :math:`\Psi_l^T\Psi_r = \Psi_r^T\Pi^T\Psi_r
   = \Psi_r^T\Psi_r = I` (:math:`\Pi^T` fixes its range). :math:`\Psi_l` is never
   needed by the reduction and is not formed (see :func:`split_projector`).
3. **Project** (eq. ``backg:thetaproj``): :math:`\tilde M = \Psi_r^T M \Psi_r`,
   :math:`\tilde D = \Psi_r^T D \Psi_r`, :math:`\tilde K = \Psi_r^T K \Psi_r`,
   :math:`\tilde F = \Psi_r^T F`, :math:`\tilde L = L \Psi_r`, dense, of order
   :math:`n_1 - n_2`.

Why this splitting is the faithful one
--------------------------------------
Inserting :math:`\Pi = \Psi_l\Psi_r^T` into the :math:`\Pi`-projected system and
multiplying by :math:`\Psi_r^T` gives eq. ``backg:thetaproj`` with
:math:`x = \Pi^T x = \Psi_r \Psi_l^T x = \Psi_r \tilde x`: the state is carried
by :math:`\Psi_r`, so :math:`\mathrm{range}(\Psi_r)` must be
:math:`\mathrm{null}(G)` (the hidden manifold, :math:`Gx = 0 \iff \Pi^T x = x`).
For *any* full-rank :math:`N` with :math:`\mathrm{range}(N) = \mathrm{null}(G)`,

.. math::  L N (N^T P(s) N)^{-1} N^T F = T(s),\qquad P(s) = s^2M + sD + K,

because :math:`x = Ny` solves the saddle-point system iff
:math:`N^T P N y = N^T F` (:math:`N^T G^T = 0` and
:math:`\mathrm{null}(N^T) = \mathrm{range}(G^T)`); another basis :math:`NT` is a
congruence and changes nothing. So the transfer function fixes only the
*range* of :math:`\Psi_r`; the orthonormal choice is then the one that

* keeps :math:`\tilde M`, :math:`\tilde K` symmetric positive definite with
  :math:`\kappa(\tilde M) \le \kappa(M)`, :math:`\kappa(\tilde K) \le \kappa(K)`
  (eigenvalue interlacing), where a general :math:`\Psi_r` multiplies the
  condition numbers by up to :math:`\kappa(\Psi_r)^2` (e.g. the other natural
  split, :math:`\Psi_l` an orthonormal basis of :math:`\mathrm{range}(\Pi)` and
  :math:`\Psi_r = \Pi^T\Psi_l`);
* is an isometry, :math:`\|\Psi_r v\| = \|v\|`: bases :math:`\tilde V` of the
  projected model and :math:`V = \Psi_r \tilde V` have the same singular values,
  so the rank decisions and orthonormalisation of the shared IRKA iteration
  are identical and the ROM equals the one ``"irka"`` builds from the same
  shifts (``lift``).

The tempting wrong choice, the range of :math:`\Pi` itself
(:math:`\mathrm{null}(G M^{-1}) = M\,\mathrm{null}(G)`) as the state space,
violates :math:`Gx = 0` and changes the transfer function unless :math:`M`
maps :math:`\mathrm{null}(G)` into itself. Both DSMS (:math:`M = 100 I`) and
TCOM (equal masses within each constrained chain) happen to satisfy that, so
only a model with a general :math:`M` tells the two apart (see the tests).

Iteration
---------
The IRKA iteration (shift/direction update, convergence and cycle tests,
stability handling, ``info`` layout) is :class:`~morsuite.reducers.irka.engine.IRKABase`, shared with
``"irka"``. Only the bases differ: one dense LU (``scipy.linalg.lu_factor``)
of :math:`\alpha^2\tilde M + \alpha\tilde D + \tilde K` per real shift or
conjugate pair, reused for the transposed (left) solve, and the reduced model
:math:`\hat M = \tilde W^T \tilde M \tilde V` etc. in the projected
coordinates (the same numbers as :math:`W^T M V` with :math:`V = \Psi_r\tilde V`,
:math:`W = \Psi_r \tilde W`).

Memory
------
Peak about :math:`8\,(n_1^2 + 3k^2 + 2k^2)` bytes (:math:`\Psi_r` kept in the
buffer of :math:`\Pi`, the projected M, D, K, one complex pencil),
:math:`k = n_1 - n_2`, i.e. some 48 :math:`n_1^2` bytes (1.6 GiB at
:math:`n_1 = 6000`, 161 GiB at 60000). It is estimated at construction and the
reducer refuses (:class:`~morsuite.errors.MemoryBudgetError`) above
``memory_budget_gib`` before anything large is allocated.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack

from ...errors import MemoryBudgetError, ModelError, SingularShiftError
from ...linalg import kernels
from .. import base as _base
from ..base import Option
from ..registry import Description
from .engine import IRKABase

__all__ = ["IRKAProjected", "ProjectedModel", "form_projector", "split_projector", "memory_estimate"]

_GIB = 1024.0 ** 3
#: column block of the pencil assembly and of the congruence (bounds temporaries to n x _BLOCK)
_BLOCK = 256


def memory_estimate(n1: int, n2: int) -> dict:
    r"""Peak memory of the projected baseline in bytes (float64), by phase.

    ``setup``: the explicit :math:`\Pi` (overwritten in place by its QR and
    then by :math:`\Psi_r`), the three projected matrices and three
    n1 x ``_BLOCK`` temporaries of the blocked congruence. ``iteration``:
    :math:`\Psi_r`, the three projected matrices, one complex pencil
    (factorised in place) and one complex k x ``_BLOCK`` assembly temporary.
    """
    n1, n2 = int(n1), int(n2)
    k = n1 - n2
    f = 8
    setup = f * (n1 * n1 + 3 * k * k + 3 * n1 * _BLOCK)
    iteration = f * (n1 * n1 + 3 * k * k + 2 * k * k + 2 * k * _BLOCK)
    small = f * (n1 * (4 * n2 + 8) + (n1 + 1) * 64)  # G M^-1, workspaces, F, L
    peak = max(setup, iteration) + small
    return {"n1": n1, "k": k, "setup_bytes": setup, "iteration_bytes": iteration,
            "peak_bytes": peak, "peak_gib": peak / _GIB}


def form_projector(fom) -> np.ndarray:
    r""":math:`\Pi = I - G^T (G M^{-1} G^T)^{-1} G M^{-1}` as a dense C-ordered array.

    ``Pi.T`` is then a Fortran-ordered view of :math:`\Pi^T`, which LAPACK
    factorises in place. One n1 x n1 allocation.
    """
    n1, n2 = fom.n1, fom.n2
    if n2 == 0:
        return np.eye(n1)
    lu = spla.splu(sp.csc_matrix(fom.M))
    Z = lu.solve(np.asfortranarray(fom.G.T.toarray()), trans="T")  # (G M^-1)^T = M^-T G^T
    S = (fom.G @ Z).T  # G M^-1 G^T
    Y = np.linalg.solve(S, Z.T)  # (G M^-1 G^T)^-1 G M^-1, n2 x n1
    Pi = np.asarray(fom.G.T @ Y)
    if not Pi.flags.c_contiguous:
        Pi = np.ascontiguousarray(Pi)
    np.negative(Pi, out=Pi)
    Pi.flat[:: n1 + 1] += 1.0
    return Pi


def _orthonormal_range_of_transpose(Pi: np.ndarray, k: int):
    r"""Orthonormal basis of :math:`\mathrm{range}(\Pi^T)` (n1 x k), overwriting ``Pi``.

    Column-pivoted Householder QR of :math:`\Pi^T` (rank k) and the first k
    columns of its Q. Returns (Psi_r, diagnostics).
    """
    A = Pi.T  # Fortran-ordered view: geqp3/orgqr work in place
    n1 = A.shape[0]
    # workspace queries with overwrite_a=1: LAPACK does not touch A in a query,
    # and f2py would otherwise copy the n1 x n1 array just to ask
    work = lapack.dgeqp3(A, lwork=-1, overwrite_a=1)[3]
    qr, _, tau, _, info = lapack.dgeqp3(A, lwork=int(work[0]), overwrite_a=1)
    if info != 0:  # pragma: no cover - LAPACK argument error
        raise ModelError(f"geqp3 failed on Pi^T (info = {info})")
    d = np.abs(np.diag(qr))
    rkk = float(d[k - 1] / d[0]) if k else 1.0
    rnext = float(d[k] / d[0]) if k < n1 else 0.0
    Qk = qr[:, :k]
    work = lapack.dorgqr(Qk, tau[:k], lwork=-1, overwrite_a=1)[1]
    Q, _, info = lapack.dorgqr(Qk, tau[:k], lwork=int(work[0]), overwrite_a=1)
    if info != 0:  # pragma: no cover
        raise ModelError(f"orgqr failed on Pi^T (info = {info})")
    return Q, {"method": "column-pivoted QR of the explicit Pi^T (LAPACK geqp3 + orgqr), Psi_r orthonormal",
               "rank": k, "r_kk_over_r_11": rkk, "r_k1k1_over_r_11": rnext,
               "in_place": bool(np.shares_memory(Q, Pi))}


def _congruence(Psi_r: np.ndarray, X) -> np.ndarray:
    r""":math:`\Psi_r^T X \Psi_r` for sparse X, in column blocks.

    A sparse-times-dense product needs a C-ordered dense factor, so a single
    ``X @ Psi_r`` would copy the whole (Fortran-ordered) :math:`\Psi_r`; blocks
    of ``_BLOCK`` columns bound that copy and keep the dense part BLAS-3.
    """
    k = Psi_r.shape[1]
    out = np.empty((k, k), order="F")  # Fortran-ordered: the pencil's one-pass assembly reads it by columns
    for j in range(0, k, _BLOCK):
        c = slice(j, min(j + _BLOCK, k))
        out[:, c] = Psi_r.T @ (X @ np.ascontiguousarray(Psi_r[:, c]))
    return out


def split_projector(Pi: np.ndarray, n2: int):
    r"""The splitting :math:`\Pi = \Psi_l \Psi_r^T`, :math:`\Psi_l^T\Psi_r = I` used here.

    :math:`\Psi_r` is an orthonormal basis of :math:`\mathrm{range}(\Pi^T) =
    \mathrm{null}(G)` and :math:`\Psi_l = \Pi\Psi_r`. ``Pi`` is not modified
    (the reducer uses the in-place variant and never forms :math:`\Psi_l`).
    """
    Pi = np.asarray(Pi, dtype=float)
    k = Pi.shape[0] - int(n2)
    Psi_r, _ = _orthonormal_range_of_transpose(np.array(Pi, order="C"), k)
    return Pi @ Psi_r, Psi_r


@dataclass
class ProjectedModel:
    r"""The dense standard second-order model of order :math:`k = n_1 - n_2` (eq. ``backg:thetaproj``).

    ``M``, ``D``, ``K`` (k x k), ``F`` (k x m), ``L`` (p x k), and ``Psi_r``
    (n1 x k, orthonormal, :math:`G\Psi_r = 0`) with which a state or basis of
    this model maps back to the index-3 one: :math:`x = \Psi_r\tilde x`.
    """

    M: np.ndarray
    D: np.ndarray
    K: np.ndarray
    F: np.ndarray
    L: np.ndarray
    Psi_r: np.ndarray = field(repr=False)
    times: dict = field(default_factory=dict)
    split: dict = field(default_factory=dict)

    @property
    def order(self) -> int:
        """The order :math:`k = n_1 - n_2` of the projected model."""
        return self.M.shape[0]

    def pencil(self, s) -> np.ndarray:
        r""":math:`s^2\tilde M + s\tilde D + \tilde K`, Fortran-ordered, assembled in column blocks."""
        cplx = isinstance(s, complex) or np.iscomplexobj(s)
        s = complex(s) if cplx else float(np.real(s))
        k = self.order
        P = np.empty((k, k), dtype=complex if cplx else float, order="F")
        if kernels.use_kernels() and all(X.flags.f_contiguous for X in (self.K, self.M, self.D)):
            return kernels.dense_pencil(self.K, self.M, self.D, s, P)  # one pass (3-7x faster, measured)
        s2 = s * s
        for j in range(0, k, _BLOCK):
            c = slice(j, min(j + _BLOCK, k))
            P[:, c] = self.K[:, c]
            P[:, c] += s2 * self.M[:, c]  # one k x _BLOCK temporary at a time
            P[:, c] += s * self.D[:, c]
        return P

    def transfer(self, s) -> np.ndarray:
        r""":math:`\tilde L (s^2\tilde M + s\tilde D + \tilde K)^{-1} \tilde F`, (p, m)."""
        s = complex(s)
        P = self.pencil(s if s.imag else s.real)
        return self.L @ sla.solve(P, self.F, overwrite_a=True, check_finite=False)

    def lift(self, X) -> np.ndarray:
        r"""Map coordinates of this model back to the index-3 state space: :math:`\Psi_r X`."""
        return self.Psi_r @ X


class IRKAProjected(IRKABase):
    r"""The paper's Algorithm 1 (SPIRKA) on the explicitly :math:`\Pi`-projected dense model.

    Same options and ``info`` layout as ``"irka"`` plus ``memory_budget_gib``.
    ``info`` adds ``memory`` (the estimate and the budget), ``setup_reused``,
    ``setup_cost`` (form_pi, split, project_model, as paid once),
    ``projected_order``, ``split`` (rank-revealing diagnostics and
    :math:`\|G\Psi_r\|`), and ``time_breakdown`` holds ``form_pi``, ``split``,
    ``project_model`` (zero when reused), ``dense_lu``, ``dense_solves`` and
    ``dense_lu_per_iteration`` (one entry per basis computation). ``lu_count``
    counts the dense LUs of the iteration plus, in the call that formed :math:`\Pi`, its two
    (a sparse LU of :math:`M`, a dense one of :math:`G M^{-1} G^T`: ``lu_count_shared``).
    """

    name = "irka-projected"
    DESCRIPTION = Description(
        label="IRKA, Pi-projected (dense)", result="second-order",
        targets="the same as irka, on the dense Pi-projected model", cost="O(n1^3) dense work",
        use_for="measuring what the paper avoids", options=("tol", "maxit", "init", "memory_budget_gib"),
        gramians="waits", stress={"maxit": 40}, page="irka", order=80)
    saddle_lu = False  # dense LUs of the projected pencil

    OPTIONS = {
        **IRKABase.OPTIONS,
        "memory_budget_gib": Option(4.0, "float", "refuse (MemoryBudgetError) if the dense projected "
                                    "model would need more than this many GiB", low=0, open_low=True),
    }

    def __init__(self, fom, **options):
        self._model = None
        super().__init__(fom, **options)  # validates options, then _check_options refuses over budget

    def _check_options(self):
        super()._check_options()
        self._check_memory()

    def _check_memory(self):
        est = memory_estimate(self.fom.n1, self.fom.n2)
        budget = self.options["memory_budget_gib"]
        self.memory = {**est, "budget_gib": budget}
        if est["peak_gib"] > budget:
            raise MemoryBudgetError(
                f"irka-projected on {self.fom.name} (n1 = {self.fom.n1}, n2 = {self.fom.n2}) would need about "
                f"{est['peak_gib']:.3g} GiB (several dense {self.fom.n1} x {self.fom.n1} float64 arrays: Pi, "
                f"its splitting Psi_r, and the projected M, D, K of order {est['k']}), above the budget "
                f"memory_budget_gib = {budget:g}; raise the option memory_budget_gib if the machine has the "
                f"memory, or use 'irka' (projector-free)")

    # -- setup: Pi, splitting, projected model (once per reducer) --------
    def projected_model(self) -> ProjectedModel:
        """The dense projected model (built on first use, then kept).

        Built under the same BLAS thread limit as ``reduce``
        (``morsuite.reducers.base.BLAS_THREADS``), also when called directly.
        """
        if self._model is None:
            self._check_memory()  # before anything large is allocated
            from threadpoolctl import threadpool_limits

            with threadpool_limits(limits=_base.BLAS_THREADS, user_api="blas"):
                self._build_model()
        return self._model

    def _build_model(self):
        """Form Pi, split it, project: the once-per-reducer setup (timed by phase)."""
        fom = self.fom
        k = fom.n1 - fom.n2
        t0 = time.perf_counter()
        Pi = form_projector(fom)
        t1 = time.perf_counter()
        Psi_r, split = _orthonormal_range_of_transpose(Pi, k)
        del Pi  # its memory now holds Psi_r
        t2 = time.perf_counter()
        mats = [_congruence(Psi_r, X) for X in (fom.M, fom.D, fom.K)]
        Ft, Lt = Psi_r.T @ fom.F, fom.L @ Psi_r
        t3 = time.perf_counter()
        gn = spla.norm(fom.G) if fom.n2 else 1.0
        split["constraint_residual"] = float(np.linalg.norm(fom.G @ Psi_r) / gn) if fom.n2 else 0.0
        self._model = ProjectedModel(*mats, Ft, Lt, Psi_r,
                                     times={"form_pi": t1 - t0, "split": t2 - t1, "project_model": t3 - t2},
                                     split=split)
        self._fresh = True

    def lift(self, X) -> np.ndarray:
        r"""Bases of the projected model mapped to the index-3 state space, :math:`\Psi_r X`."""
        return self.projected_model().lift(X)

    def _setup(self):
        self._n_lu = 0
        self._t_lu = 0.0
        self._t_solve = 0.0
        self._lu_times = []
        self._fresh = False
        pm = self.projected_model()
        if self._fresh:
            return dict(pm.times)
        return {key: 0.0 for key in pm.times}

    def _lu_count(self):
        return self._n_lu

    def _phase_times(self):
        return {"dense_lu": self._t_lu, "dense_solves": self._t_solve}

    # -- bases: dense solves with the projected pencil -------------------
    def _factor(self, a):
        pm = self._model
        t0 = time.perf_counter()
        lu, piv = sla.lu_factor(pm.pencil(a), overwrite_a=True, check_finite=False)
        dt = time.perf_counter() - t0
        self._n_lu += 1
        self._t_lu += dt
        self._lu_times[-1] += dt
        u = np.abs(np.diag(lu))
        ratio = float(u.min() / u.max()) if u.size and u.max() > 0 else 0.0
        tol = self.options["pivot_tol"]
        if tol > 0 and not ratio > tol:
            exc = SingularShiftError(
                f"projected pencil at s = {a} is singular to working precision (smallest/largest pivot "
                f"{ratio:.2e} <= pivot_tol {tol:.1e}): the shift is at or next to a pole of the system")
            exc.shift = a
            raise exc
        return lu, piv

    def _solve(self, lu_piv, rhs, trans, a):
        t0 = time.perf_counter()
        x = sla.lu_solve(lu_piv, rhs, trans=1 if trans else 0, check_finite=False)
        self._t_solve += time.perf_counter() - t0
        if not np.all(np.isfinite(x)):
            exc = SingularShiftError(f"projected solve at s = {a} produced non-finite values")
            exc.shift = a
            raise exc
        return x

    def _system(self):
        pm = self._model
        return pm.M, pm.D, pm.K, pm.F, pm.L

    def _lift(self, V):
        r""":math:`\Psi_r V`: the basis in the index-3 model's positions."""
        return self._model.lift(V)

    def _begin_bases(self):
        self._lu_times.append(0.0)

    def _reduce(self, r):
        fresh_before = self._model is None
        rom, info = super()._reduce(r)
        pm = self._model
        info["time_breakdown"]["dense_lu_per_iteration"] = list(self._lu_times)
        info["memory"] = dict(self.memory)
        info["setup_reused"] = not fresh_before
        info["setup_cost"] = dict(pm.times)
        # the setup's LUs (sparse of M, dense of G M^-1 G^T), shared by every r (reducers.outcome)
        info["lu_count_shared"] = 2 if self.fom.n2 else 0
        if fresh_before:
            info["lu_count"] += info["lu_count_shared"]
        info["projected_order"] = pm.order
        info["split"] = dict(pm.split)
        return rom, info

