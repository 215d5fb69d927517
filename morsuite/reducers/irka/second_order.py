r"""Projector-free IRKA for second-order index-3 systems (the paper's Algorithm 2).

Each iteration takes r interpolation points :math:`\alpha_i` (closed under
conjugation, in the open right half-plane) with right and left tangential
directions :math:`b_i`, :math:`c_i`, and solves

.. math::

    \begin{bmatrix} \alpha_i^2 M + \alpha_i D + K & G^T \\ G & 0 \end{bmatrix}
    \begin{bmatrix} v_i \\ \lambda_i \end{bmatrix} = \begin{bmatrix} F b_i \\ 0 \end{bmatrix},
    \qquad
    \begin{bmatrix} \alpha_i^2 M + \alpha_i D + K & G^T \\ G & 0 \end{bmatrix}^T
    \begin{bmatrix} w_i \\ \gamma_i \end{bmatrix} = \begin{bmatrix} L^T c_i \\ 0 \end{bmatrix}

(Lemma 1 of the paper: :math:`v_i = \Pi^T v_i` solves the :math:`\Pi`-projected
system, so :math:`\Pi` is never formed). Real bases are formed from real and
imaginary parts, orthonormalised and projected back onto :math:`\mathrm{null}(G)`
(``kernel_projection``); the reduced model is :math:`\hat M = W^T M V`,
:math:`\hat D = W^T D V`, :math:`\hat K = W^T K V`, :math:`\hat F = W^T F`,
:math:`\hat L = L V`. The iteration, the shift update and the safeguards are
those of :class:`~morsuite.reducers.irka.engine.IRKABase` (:mod:`~morsuite.reducers.irka.shift_update`,
:mod:`~morsuite.reducers.irka.safeguards`).

Options: :attr:`IRKA.OPTIONS`, the shared table plus ``refine`` (1),
``refine_when`` ("ill-conditioned"), ``refine_precision`` ("extended"; one
step of iterative refinement with an extended-precision residual,
:mod:`morsuite.linalg.refine`), ``kernel_projection`` (True), ``kernel_tol``
(1e-14) and ``check_solves`` ("first").

Cost per iteration: one sparse LU of the saddle-point matrix per real shift or
conjugate pair (``info["lu_count"]``); the transposed (left) solve shares it,
refinement adds one sparse product and one pair of triangular solves per
refined solve; the kernel projection one sparse LU of :math:`G G^T` per
reduction. Design notes and measurements: ``docs/design/irka.md``.
"""

from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np
import scipy.sparse.linalg as spla

from ...errors import SingularShiftError
from ...linalg.dense import cholesky_qr2, right_solve
from ...linalg.orthonormal import gram_schmidt
from ...linalg.refine import SaddleOperator, refined_solve
from ..base import Option
from ..registry import Description
from .engine import IRKABase
from .shift_solves import default_threads, map_dask, map_threads

__all__ = ["IRKA"]


class IRKA(IRKABase):
    """The paper's Algorithm 2: bases from sparse saddle-point solves, no projector.

    ``reduce(r)`` returns a :class:`~morsuite.rom.SecondOrderROM` of order r
    (2r first-order states), or smaller if the bases lose numerical rank (see
    :mod:`~morsuite.reducers.irka.engine`).
    """

    name = "irka"
    DESCRIPTION = Description(
        label="IRKA (paper, second-order)", result="second-order",
        targets="interpolation at r mirrored poles (the paper)",
        cost="one per real shift or pair per iteration", use_for="reproducing the paper; cheap when it converges",
        options=("tol", "maxit", "init", "init_shifts", "update", "safeguard", "refine"), default=True,
        gramians="waits", stress={"maxit": 40}, page="irka", order=10)

    OPTIONS = {
        **IRKABase.OPTIONS,
        "refine": Option(1, "int", "steps of iterative refinement of each saddle-point solve with the "
                         "same LU (0: none)", low=0),
        "refine_when": Option("ill-conditioned", "choice", "refine every solve, or only the solves of an "
                              "iteration that follows one whose bases were ill-conditioned (ill_cond_tol): "
                              "the forward error of a solve matters only through an ill-conditioned basis",
                              choices=("ill-conditioned", "always")),
        "refine_precision": Option("extended", "choice", "precision of the refinement residual: extended "
                                   "(double-double, linalg.dd_kernels, where numba imports; else np.longdouble, "
                                   "which equals working where longdouble is double) or working",
                                   choices=("extended", "working")),
        "kernel_projection": Option(True, "bool", "project the orthonormalised bases back onto null(G) "
                                    "(rounding in the orthonormalisation moves directions of singular value "
                                    "sigma out of it by eps/sigma)"),
        "kernel_tol": Option(1e-14, "float", "kernel_projection leaves an orthonormal basis unchanged when the "
                             "component it would remove has norm at most this (per column, RMS)",
                             low=0, high=1, open_high=True),
        "check_solves": Option("first", "choice", "backward-error check of the saddle-point solves: the first "
                               "solve with each LU (it probes the stability of the factors, which the "
                               "transposed solve shares) or all of them",
                               choices=("first", "all")),
        "solver_threads": Option(0, "int", "threads that factor and solve an iteration's shifts concurrently "
                                 "(executor 'threads'); 0: automatic, 2 on two or more cores (the LUs release "
                                 "the GIL)", low=0),
        "executor": Option("threads", "choice", "what runs the shifts' solves: a thread pool in this process, "
                           "or the current dask.distributed client ('dask'); the result does not depend on it",
                           choices=("threads", "dask")),
    }

    GROUPS = {**IRKABase.GROUPS,
              "solves": IRKABase.GROUPS["solves"].extended("refine_when", "refine_precision", "kernel_projection",
                                                           "kernel_tol", "check_solves", "executor")}

    #: bases with fewer entries are made orthonormal in order (``_map_bases``)
    PARALLEL_BASES_MIN = 1 << 20

    def _setup(self):
        self._solver = self.fom.new_solver(cache_size=0, pivot_tol=self.options["pivot_tol"])
        self._refiner = SaddleOperator(self._solver.pattern)
        self._local = threading.local()  # a refiner per solver thread: its cache holds one shift's entries
        self._threads = self.options["solver_threads"] or default_threads(self._solver.backend)
        G = self.fom.G
        # the orthogonal projector onto null(G), X - G^T (G G^T)^{-1} G X, through a sparse LU
        # of the n2 x n2 matrix G G^T (well conditioned: checked when the model was built);
        # never formed, no dense n1 x n2 array
        self._GGt = None
        self._GGt_lock = threading.Lock()
        if self.options["kernel_projection"] and G.shape[0]:
            self._GGt = spla.splu((G @ G.T).tocsc())
            self._support = np.unique(G.tocsr().indices)  # the columns of G with an entry
            self._Gs = G.tocsc()[:, self._support].tocsr()
        return {}

    def _solve(self, lu, rhs, trans, a):
        """Saddle-point solve, refined ``refine`` times with the same LU when this iteration refines."""
        steps = self.options["refine"] if self._refining() else 0
        if steps == 0:
            return lu.solve(rhs, trans=trans)
        if threading.current_thread() is threading.main_thread():
            op = self._refiner
        else:
            op = getattr(self._local, "op", None) or SaddleOperator(self._solver.pattern)
            self._local.op = op
        return refined_solve(lu, rhs, trans, a, op, steps=steps, ext=self.options["refine_precision"] == "extended")

    def _map_shifts(self, fn, jobs):
        """The shifts' jobs on the executor of option ``executor`` (:mod:`~morsuite.reducers.irka.shift_solves`)."""
        o = self.options
        if o["executor"] == "dask":
            steps = o["refine"] if self._refining() else 0
            return map_dask(self, jobs, steps, o["refine_precision"] == "extended", o["check_solves"] == "all")
        return map_threads(fn, jobs, self._threads)

    def _map_bases(self, fn, bases):
        """The right and left bases made orthonormal on ``solver_threads`` threads (BLAS and the
        LAPACK calls release the GIL; the sparse LU of G G^T is used under a lock). Each basis
        goes through the same operations whatever the thread count: the same bits. Bases below
        2^20 entries (8 MB) are done in order: their dense work is too short for two threads
        to pay (the GIL is held between the calls into BLAS)."""
        big = all(X is not None and X.size >= self.PARALLEL_BASES_MIN for X in bases)
        return map_threads(fn, bases, self._threads if big else 1)

    def _outcome(self, *args, **kwargs):
        rom, info = super()._outcome(*args, **kwargs)
        info.update(solver_threads=self._threads if self.options["executor"] == "threads" else None,
                    executor=self.options["executor"])
        return rom, info

    def _refining(self) -> bool:
        o = self.options
        return o["refine"] > 0 and (o["refine_when"] == "always" or getattr(self, "_ill_conditioned", False))

    def _second(self, lu):
        if self.options["check_solves"] == "all" or lu.matrix is None:
            return lu
        return replace(lu, matrix=None)  # the same factors, unchecked

    def _restrict(self, X):
        r"""X orthogonally projected onto :math:`\mathrm{null}(G)` and re-orthonormalised in order.

        Lemma 1 puts the raw solutions in :math:`\mathrm{null}(G)` (to the solve
        accuracy), but orthonormalising an ill-conditioned basis moves a direction of
        singular value :math:`\sigma` out of it by about :math:`\varepsilon/\sigma`.
        :math:`X - G^T (G G^T)^{-1} G X`, applied twice, changes only the rows of X that
        G touches (its columns with an entry) and costs :math:`O(\mathrm{nnz}(G) k)` plus the
        sparse LU of :math:`G G^T` made in ``_setup``; X is returned unchanged when the removed
        part is at most ``kernel_tol`` (RMS per column), else re-orthonormalised with one pass
        over X (one Cholesky-QR step whose Gram matrix comes from those rows) when the result is
        well conditioned, by Cholesky-QR2 or Gram-Schmidt otherwise."""
        if self._GGt is None or X.shape[1] == 0:
            return X
        rows = self._support_rows(X.shape[0])
        Xs = X[rows]
        Cs = self._range_part_rows(Xs)  # range(G^T) lies on these rows: the rest of X is in null(G)
        if np.linalg.norm(Cs) <= self.options["kernel_tol"] * np.sqrt(X.shape[1]):
            return X  # X is in null(G) to rounding (a well-conditioned basis): nothing to remove
        Ys = Xs - Cs
        Ys -= self._range_part_rows(Ys)  # twice is enough
        # re-orthonormalise in order (X is orthonormal up to the removed part); a direction
        # almost wholly in range(G^T) carries no state and is dropped (Gram-Schmidt). When
        # every column kept most of its norm, X is near-orthonormal: its Gram matrix is
        # I - Xs^T Xs + Ys^T Ys (X^T X = I to rounding), its Cholesky factor R well conditioned
        # and Y R^-1 orthonormal to rounding; one pass over X (docs/design/irka.md)
        gram = np.eye(X.shape[1]) - Xs.T @ Xs + Ys.T @ Ys
        if np.min(np.diag(gram)) > 0.25:
            try:
                R = np.linalg.cholesky(gram).T
                sv = np.linalg.svd(R, compute_uv=False)
                if sv[-1] > 0.25 * sv[0]:
                    Q = right_solve(X, R)
                    Q[rows] = right_solve(Ys, R)
                    return Q
            except np.linalg.LinAlgError:
                pass
        Y = np.array(X, order="F")
        Y[rows] = Ys
        if np.min(np.linalg.norm(Y, axis=0)) > 0.5:
            try:
                return cholesky_qr2(Y)[0]
            except np.linalg.LinAlgError:
                pass
        return gram_schmidt(Y, 1e-2, pivot=False)[0]

    def _support_rows(self, nrows):
        """The rows of an (nb n1)-row basis that G touches: the columns of G holding an entry,
        in each of the nb blocks of n1 rows (one block here; a first-order variant stacks two)."""
        n1 = self.fom.n1
        return np.concatenate([b * n1 + self._support for b in range(nrows // n1)])

    def _range_part_rows(self, Xs):
        """:math:`G^T (G G^T)^{-1} G X` on the support rows (``_support_rows``), from the
        support rows Xs of X: per n1-row block, :math:`G_s^T (G G^T)^{-1} G_s X_s` with
        :math:`G_s` the columns of G holding an entry. Elsewhere the product is zero."""
        ns, k = self._support.size, Xs.shape[1]
        nb = Xs.shape[0] // ns
        Xb = Xs.reshape(nb, ns, k).transpose(1, 0, 2).reshape(ns, nb * k) if nb > 1 else Xs
        with self._GGt_lock:  # SuperLU's solve is not documented as thread-safe
            Y = self._GGt.solve(np.asarray(self._Gs @ Xb))
        C = np.asarray(self._Gs.T @ Y)
        return C.reshape(ns, nb, k).transpose(1, 0, 2).reshape(nb * ns, k) if nb > 1 else C

    def _lu_count(self):
        return self._solver.stats.factorizations

    def _phase_times(self):
        st = self._solver.stats
        return {"factorizations": st.factor_time_s + st.assemble_time_s, "solves": st.solve_time_s}

    def _system(self):
        f = self.fom
        return f.M, f.D, f.K, f.F, f.L

    def _factor(self, a):
        try:
            return self._solver.factor(a)
        except SingularShiftError as exc:
            exc.shift = a
            raise

