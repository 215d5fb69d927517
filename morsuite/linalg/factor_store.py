r"""The column store of an LR-ADI factor (:class:`FactorStore`): plain, or compressed as it grows.

Used by :class:`~morsuite.linalg.adi_iteration.ADIIteration`, one store per equation; the class
docstring states the compression's steps, its error bound and its cost, and the measurements are
in ``docs/design/lradi.md``.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.linalg import blas as _blas
from scipy.linalg import cholesky as _cholesky
from scipy.linalg import qr as _qr
from scipy.linalg import solve_triangular as _solve_triangular
from scipy.linalg.lapack import dtrcon as _dtrcon

__all__ = ["FactorStore"]


def _in_place(out, X):
    """X = out, unless the BLAS wrapper already wrote into X (it does for F-ordered columns)."""
    if not np.may_share_memory(out, X):
        X[...] = out


class FactorStore:
    r"""The columns of a low-rank factor :math:`Z = [Z_1; Z_2]` (n1-blocks), kept plain or compressed.

    ``tol = 0``: the columns are stored as appended (blocks grown by doubling: a run should
    not reserve ``maxiter`` columns it may never use).

    ``tol > 0``: the columns are stored as appended while both blocks together hold at most
    ``plain_bytes`` (no compression where the factor fits: it keeps every direction, its column
    layout, and costs nothing; at n1 = 2e5 the DSMS's 146 columns are 0.47 GB); once appending
    would exceed that, the columns so far wait for a first compression, and from then on the
    factor is compressed as it grows. The store holds
    :math:`ZZ^T = QFF^TQ^T` with :math:`Q = [Q_1; Q_2]` orthonormal (stacked, k columns)
    and F diagonal. Appended columns B are written straight into the blocks after Q and
    compressed once :math:`b = \max(\texttt{chunk}, (\texttt{GROWTH} - 1)k)` of them
    wait (``GROWTH`` 1.5: Q and the waiting columns reach 1.5 times the last rank), by
    reorthogonalised block classical Gram-Schmidt (BCGS2), all BLAS 3 and in place,
    the two blocks never stacked:

    1. :math:`C_1 = Q^TB`, :math:`B \leftarrow B - QC_1`; :math:`B = XR_1` by
       Cholesky-QR (:math:`R_1^TR_1 = B_1^TB_1 + B_2^TB_2`, :math:`X = BR_1^{-1}`);
    2. on the normalised X, one product gives :math:`H = Q^TX` and :math:`X^TX`;
       :math:`X - QH = Q_bR_2` with :math:`R_2^TR_2 = X^TX - H^TH` (Cholesky; accepted
       while its condition number is at most ``FOLD_COND_MAX``, 100, so that the
       difference loses no accuracy: after step 1, :math:`X^TX \approx I` and H is tiny), so that
       :math:`B = Q(C_1 + HR_1) + Q_bR_2R_1` and
       :math:`ZZ^T = [Q, Q_b]\,\hat F\hat F^T[Q, Q_b]^T`,
       :math:`\hat F = [[F, C_1 + HR_1], [0, R_2R_1]]`;
    3. the SVD :math:`\hat F = U\Sigma V^T` truncates: singular values below ``tol``
       times :math:`\sigma_1(Z)` are dropped, and
       :math:`Q \leftarrow [Q, Q_b]U_t = [Q, X]\,[[U_Q - HW], [W]]`,
       :math:`W = R_2^{-1}U_b`: one in-place product by row blocks, into which the
       second pass's :math:`X - QH` is folded (it is never formed); :math:`F = \Sigma_t`.

    A Cholesky-QR is accepted while the Gram matrix's condition number is at most
    ``GRAM_COND_MAX`` (1e8: a loss of orthogonality of at most about
    :math:`10^8\varepsilon` after step 1, :math:`O(\varepsilon)` after step 2). When
    step 1's Cholesky fails or the block is worse conditioned (ADI columns of close
    shifts, a rank-deficient block), that normalisation is a Householder QR of a
    stacked copy and the SVD of its R, which drops only numerically null directions
    (singular values below :math:`10\varepsilon` times a lower bound of
    :math:`\sigma_1(Z)`); when step 2's Cholesky fails or exceeds ``FOLD_COND_MAX``,
    :math:`X - QH` is formed and normalised as in step 1, Cholesky-QR or Householder
    (each Householder fallback counted in ``householder``). A compression changes :math:`ZZ^T`
    by at most :math:`\mathrm{tol}^2\sigma_1(Z)^2` (the truncation: the rank-revealing
    SVD of Z itself) plus :math:`20\sqrt{b}\,\varepsilon\,\sigma_1(Z)^2` (the
    absorption). Every kept column is a combination of appended ones, so the store
    commutes with any projection applied to the rows (the observability position
    block is kept unprojected, see :class:`~morsuite.linalg.adi_iteration.ADIIteration`).

    Memory: plain, the blocks grow by doubling and are trimmed to the columns in use at
    :meth:`finish` when more than a quarter of them is unused; compressed, by an eighth (at least ``chunk`` columns); Q and the
    waiting columns share the blocks (``k_peak``: the most held at once, about
    ``GROWTH`` times the kept rank, at least the rank plus ``chunk``, instead of every
    column produced).

    Cost of a compression with k columns in Q, b waiting and t kept: :math:`8n_1kb`
    (step 1's two products with Q) :math:`+ 4n_1(k+b)b` (step 2's one product)
    :math:`+ 4n_1b^2` (step 1's Gram matrix and triangular solve)
    :math:`+ 4n_1(k+b)t` (the rotation) flops, no n1-sized copy (a Householder fallback
    adds a QR of a stacked :math:`2n_1 \times b` copy). With b = k/2 and t = k that is
    about :math:`28n_1k` flops per column produced, against about :math:`38n_1k` for
    the earlier store (two full Gram-Schmidt passes per 64 columns, a Householder QR
    with Q formed, its rotation and a stacked copy per block, a separate truncation
    rotating Q); measured in ``docs/design/lradi.md``.
    """

    #: truncate when Q has grown to GROWTH times the rank of the last truncation
    GROWTH = 1.5
    #: Cholesky-QR accepted while the Gram matrix's condition number (cond(R)^2) is at most this
    GRAM_COND_MAX = 1e8
    #: the second pass's Gram matrix X^TX - H^TH (Pythagoras) accepted while its condition number is at most this
    FOLD_COND_MAX = 1e2
    #: bytes of one row block of the Householder fallback's tall-skinny QR (a block stays in the cache)
    TSQR_BYTES = 2 ** 21

    def __init__(self, n1, tol=0.0, chunk=64, plain_bytes=0.0):
        self.n1, self.tol, self.chunk = int(n1), float(tol), int(chunk)
        self.plain_cols = int(plain_bytes // (16 * max(self.n1, 1)))  # columns kept plain before compressing
        self.compressing = self.tol > 0 and self.plain_cols == 0
        self.Z1 = np.empty((self.n1, 0), order="F")
        self.Z2 = np.empty((self.n1, 0), order="F")
        self.k = 0           # plain: columns stored; compressed: columns of Q
        self.nb = 0          # compressed: appended columns waiting in Z[:, k:k + nb]
        self.F = np.zeros((0, 0))
        self.sigma1 = 0.0    # compressed: a lower bound of sigma_1(Z) (a column norm, a truncation's sigma_1)
        self.columns = 0     # columns appended in all
        self.compressions = 0  # absorptions of waiting columns, each with its truncation
        self.householder = 0   # normalisations that fell back to Householder
        self.k_truncated = 0   # rank after the last truncation
        self.k_peak = 0        # most columns held at once (compressed: Q and the waiting ones)
        self.t_compress = 0.0
        self.done = False

    def _reserve(self, cols):
        """Room for ``cols`` columns: plain, doubled (amortised appends); compressed, ``cols`` plus
        an eighth or one ``chunk``, whichever is more (its column count is bounded by the truncation
        rule, and a doubled Q at n1 = 1e6 would hold gigabytes of unused columns)."""
        if cols > self.Z1.shape[1]:
            if not self.compressing:
                room = max(2 * cols, 32)
                if self.tol > 0:  # plain until plain_cols: no room beyond the switch to compression
                    room = max(cols, min(room, self.plain_cols + self.chunk))
            else:
                room = cols + max(self.chunk, cols // 8)
            used = self.k + self.nb
            for name in ("Z1", "Z2"):
                Z = np.empty((self.n1, room), order="F")
                Z[:, :used] = getattr(self, name)[:, :used]
                setattr(self, name, Z)

    def _trim(self):
        """Release the unused columns of the blocks (one block copied at a time) where more than a quarter
        of the columns in use (at least 8) is unused: the factor is kept for the reducer's life, and a
        doubled store can hold twice its columns; a smaller slack is not worth a copy of the factor (at
        dsms(2e5), 114 columns in a room of 128: 365 MB copied to free 45 MB)."""
        for name in ("Z1", "Z2"):
            Z = getattr(self, name)
            if Z.shape[1] > self.k + max(8, self.k // 4):
                setattr(self, name, np.array(Z[:, :self.k], order="F"))

    def append(self, c, X1, X2):
        """Append the columns c [X1; X2]."""
        j = X1.shape[1]
        self.columns += j
        if not self.compressing:
            if self.tol == 0 or self.k + j <= self.plain_cols:
                self._reserve(self.k + j)
                np.multiply(X1, c, out=self.Z1[:, self.k:self.k + j])
                np.multiply(X2, c, out=self.Z2[:, self.k:self.k + j])
                self.k += j
                if self.tol:
                    self.k_peak = max(self.k_peak, self.k)
                return
            self.compressing = True  # the plain columns reached plain_bytes: they wait for the first compression
            self.k, self.nb = 0, self.k
        t0 = time.perf_counter()
        s = self.k + self.nb
        self._reserve(s + j)
        np.multiply(X1, c, out=self.Z1[:, s:s + j])  # straight into the waiting room after Q
        np.multiply(X2, c, out=self.Z2[:, s:s + j])
        self.nb += j
        self.k_peak = max(self.k_peak, s + j)
        self.t_compress += time.perf_counter() - t0
        if self.nb >= max(self.chunk, (self.GROWTH - 1) * self.k_truncated):
            self._compress()

    def _project(self, k, lo, hi):
        r"""One block Gram-Schmidt pass of the columns lo:hi against Q: :math:`H = Q^TX`,
        :math:`X \leftarrow X - QH` in place; returns H."""
        H = self.Z1[:, :k].T @ self.Z1[:, lo:hi]
        H += self.Z2[:, :k].T @ self.Z2[:, lo:hi]
        self._subtract(k, lo, hi, H)
        return H

    def _subtract(self, k, lo, hi, H):
        r""":math:`X \leftarrow X - QH` in place for the columns X = lo:hi and Q the first k (BLAS 3)."""
        for Z in (self.Z1, self.Z2):
            _in_place(_blas.dgemm(-1.0, Z[:, :k], H, 1.0, Z[:, lo:hi], overwrite_c=1), Z[:, lo:hi])

    @staticmethod
    def _cholesky(G, cond_max):
        """The upper Cholesky factor R of the Gram matrix G, or None when the Cholesky fails or
        cond(R)^2 > ``cond_max`` (LAPACK trcon's 1-norm estimate)."""
        try:
            R = _cholesky(G, lower=False, check_finite=False)
        except np.linalg.LinAlgError:
            return None
        return R if _dtrcon(R, norm="1", uplo="U")[0] ** 2 * cond_max >= 1.0 else None

    def _normalise(self, lo, hi, floor):
        r"""Orthonormalise the columns X = lo:hi in place: X = X_new R, X_new the first t of them.

        Cholesky-QR (:math:`X^TX = R^TR`, :math:`X \leftarrow XR^{-1}` in place, t = hi - lo) when
        :meth:`_cholesky` accepts the Gram matrix; else Householder on a stacked copy and the SVD
        of its R, keeping the t directions with singular values above ``floor``. Returns (R, t),
        R t x (hi - lo)."""
        X1, X2 = self.Z1[:, lo:hi], self.Z2[:, lo:hi]
        G = X1.T @ X1
        G += X2.T @ X2
        R = self._cholesky(G, self.GRAM_COND_MAX)
        if R is not None:
            for X in (X1, X2):
                _in_place(_blas.dtrsm(1.0, R, X, side=1, lower=0, overwrite_b=1), X)
            return R, hi - lo
        self.householder += 1
        parts, Qr, Rh = self._tsqr(X1, X2)
        U, s, Vt = np.linalg.svd(Rh)
        t = int(np.sum(s > floor))
        W = Qr @ U[:, :t]  # the stacked blocks' Q times W is the new X
        for (X, i, j, q, lo_w) in parts:
            X[i:j, :t] = q @ W[lo_w:lo_w + q.shape[1]]
        return s[:t, None] * Vt[:t], t

    def _tsqr(self, X1, X2):
        r"""Householder QR of the stacked :math:`[X_1; X_2]` by row blocks (tall-skinny QR), no stacked copy.

        Each block of ``TSQR_BYTES`` (at least 4b rows) is factored on its own, :math:`X_{(i)} = Q_iR_i`, and
        the stacked :math:`R_i` once more, :math:`[R_1; R_2; \ldots] = Q_rR`: :math:`X = \mathrm{diag}(Q_i)\,Q_rR`,
        as backward stable as one Householder QR. LAPACK's panel of a QR of :math:`2n_1` rows is level-2 BLAS
        streaming the panel from memory once per column; blocks that fit in the cache keep it linear in
        :math:`n_1` (at n1 = 2e5, b = 64: 18.6 s for one stacked QR against 1.1 s at 2e4, ``docs/design/lradi.md``).
        Returns the blocks ``(X, row0, row1, Q_i, row of Q_r)``, :math:`Q_r` and R."""
        b = X1.shape[1]
        rows = max(4 * b, self.TSQR_BYTES // (8 * max(b, 1)))
        parts, Rs, at = [], [], 0
        for X in (X1, X2):
            for i in range(0, self.n1, rows):
                j = min(i + rows, self.n1)
                q, r = _qr(X[i:j], mode="economic", check_finite=False)
                parts.append((X, i, j, q, at))
                Rs.append(r)
                at += r.shape[0]
        Qr, R = _qr(np.vstack(Rs), mode="economic", check_finite=False)
        return parts, Qr, R

    def _compress(self):
        """Absorb the waiting columns and truncate: one rotation of [Q, X] (see the class)."""
        b = self.nb
        t0 = time.perf_counter()
        k, hi = self.k, self.k + b
        eps = np.finfo(float).eps
        C = self._project(k, k, hi) if k else np.zeros((0, b))         # pass 1: B - QC
        R1, t = self._normalise(k, hi, 10 * eps * self.sigma1)          # = X R1
        r1 = np.sqrt(np.max(np.sum(R1 * R1, axis=0), initial=0.0))      # <= ||R1||_2 <= sqrt(b) r1
        self.sigma1 = max(self.sigma1, r1)                               # a column of Z: <= sigma_1(Z)
        Z1, Z2 = self.Z1, self.Z2
        folded = False
        if t:  # pass 2 on the normalised X: H = Q^T X, and X - QH = Q_b R2 by Cholesky-QR of its Gram
            HG = Z1[:, :k + t].T @ Z1[:, k:k + t]                        # [H; X^T X] in one product
            HG += Z2[:, :k + t].T @ Z2[:, k:k + t]
            H = HG[:k]
            R2 = self._cholesky(HG[k:] - H.T @ H, self.FOLD_COND_MAX)  # Pythagoras: accurate if ||H|| < 1
            folded = R2 is not None
            if not folded:  # X - QH formed, and normalised (Householder if need be)
                if k:
                    self._subtract(k, k, k + t, H)
                R2, t = self._normalise(k, k + t, 10 * eps * self.sigma1 / max(np.sqrt(b) * r1, 1e-300))
            C += H @ R1
            Rb = R2 @ R1                                                 # B = QC + Q_b Rb
        else:
            Rb = R1
        # ZZ^T = [Q, Q_b] F F^T [Q, Q_b]^T, F = [[F, C], [0, Rb]]; its SVD truncates
        U, s, _ = np.linalg.svd(np.block([[self.F, C], [np.zeros((t, self.F.shape[1])), Rb]]),
                                full_matrices=False)
        kept = int(np.sum(s > self.tol * s[0])) if s.size and s[0] > 0 else 0
        U = U[:, :kept]
        if folded:  # [Q, (X - QH) R2^{-1}] U = [Q, X] [[U_Q - H W], [W]], W = R2^{-1} U_b
            W = _solve_triangular(R2, U[k:], lower=False, check_finite=False)
            U = np.vstack([U[:k] - H @ W, W])
        self._rotate(U)
        self.F = np.diag(s[:kept])
        self.sigma1 = max(self.sigma1, s[0] if s.size else 0.0)
        self.k_truncated, self.nb = kept, 0
        self.compressions += 1
        self.t_compress += time.perf_counter() - t0

    def _rotate(self, X):
        """:math:`Q \\leftarrow QX` in place (X is k x t, t <= k), by row blocks."""
        r, t = X.shape
        step = max(1, 2 ** 22 // max(r, 1))
        for Z in (self.Z1, self.Z2):
            for i in range(0, self.n1, step):
                Z[i:i + step, :t] = Z[i:i + step, :r] @ X
        self.k = t

    def finish(self):
        """Absorb the waiting columns (and truncate), then turn Q into the factor :math:`QF`
        (in place); once. The blocks are then trimmed to the columns in use."""
        if self.done:
            return
        if not self.compressing:  # plain: tol = 0, or the factor stayed within plain_bytes
            self._trim()
            self.done = True
            return
        if self.nb:
            self._compress()
        t0 = time.perf_counter()
        self._rotate(self.F)  # F is diagonal: Q U_t Sigma_t
        self._trim()
        self.done = True
        self.t_compress += time.perf_counter() - t0

    def blocks(self):
        """The factor's blocks (n1 x rank views); after :meth:`finish` when compressing."""
        if not self.done:
            raise RuntimeError("FactorStore.blocks before finish")
        return self.Z1[:, :self.k], self.Z2[:, :self.k]
