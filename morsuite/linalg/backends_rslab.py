r"""rslab's sparse factorizations (MIT, pure Rust; a default dependency): the supernodal LU and, at
complex shifts of models with symmetric M, D and K, the supernodal Bunch-Kaufman LDL^T.

``"rslab"`` (:func:`rslab_factor`, the backend's entry in :class:`~morsuite.linalg.saddle.SaddlePointSolver`)
    rslab's supernodal left-looking LU (``path="lu"``) with threshold partial pivoting: its
    analysis (MC64 matching, the fill-reducing ordering of least fill among AMD, AMF, RCM and
    nested dissection) once per pattern from the pattern's magnitudes; per shift one numeric
    factorization on one thread (:data:`RSLAB_SETTINGS`). At a complex shift of a model whose M, D
    and K are symmetric, the LDL^T of :class:`RslabLDLT` instead (half the fill; 1.3-1.6x faster on
    fem_block), its LU the first fallback. The fast backend on 3D solids.

The helpers (the library's import, the pattern's magnitudes, values kept with the pattern) are those
of :mod:`morsuite.linalg.backends_ext`. Measurements: ``docs/design/backends.md`` (2026-11-27, 2026-11-28).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import SingularShiftError
from .backends_ext import _magnitudes, _rslab, _stored, _symmetric_blocks

__all__ = ["RSLAB_LDLT_SETTINGS", "RSLAB_SETTINGS", "RslabLDLT", "RslabLU", "rslab_factor", "rslab_ldlt_symbolic",
           "rslab_symbolic"]

#: rslab's settings of every analysis and factorization: one worker (the factor is the same bits
#: for every thread count; one thread keeps a solver thread to one core) and the ordering race
#: open to nested dissection at every size (the cheap orderings alone filled 1.34x more on
#: fem_block(4000) and factored 2x slower: docs/design/backends.md, 2026-11-27)
RSLAB_SETTINGS = {"threads": 1, "race_nd_min_n": 0, "race_nd_min_work": 0}


def rslab_symbolic(pattern):
    """rslab's supernodal-LU analysis of the pattern (``path="lu"``), made once per pattern.

    Analysed from the matrix of the pattern's magnitudes :math:`|m| + |d| + |k| + |g|` (its MC64
    row matching and the fill-reducing ordering -- the smallest fill of minimum degree, minimum
    fill, RCM and nested dissection, :data:`RSLAB_SETTINGS` -- depend on the pattern only).
    Returns the ``LuSymbolic``; its ``factor_nnz`` and ``estimate_memory()["factor_flops"]`` are the
    predicted fill and work. Cost: the orderings' race (0.1-4 s from n1 = 4e3 to 2e4 on fem_block).
    """
    def make():
        rslab = _rslab()
        data, ind, ptr = _magnitudes(pattern)
        N = ptr.size - 1
        A = sp.csc_matrix((np.asarray(data, dtype=float), ind.copy(), ptr.copy()), shape=(N, N))
        return rslab.analyze(A, path="lu", **RSLAB_SETTINGS)
    return _stored(pattern, ("rslab",), make)


class RslabLU:
    r"""rslab's supernodal LU (``path="lu"``; MIT, pure Rust) of an equilibrated saddle matrix ``As``.

    :math:`P_r^T A_s P_c = LU` with threshold partial pivoting (0.1) on the analysis of
    :func:`rslab_symbolic`; one numeric factorization per shift, real or complex by the values'
    type, on one thread. ``solve(b, trans)`` as SuperLU's (``"T"``: the plain transpose). Taken
    where :class:`RslabLDLT` does not apply (M, D or K not symmetric) and as its fallback.
    Raises :class:`~morsuite.errors.SingularShiftError` on a zero pivot (the solver then tries SuperLU).
    """

    def __init__(self, As, pattern):
        sym = rslab_symbolic(pattern)
        self.dtype = np.complex128 if np.iscomplexobj(As.data) else np.float64
        self.shape = As.shape
        try:
            self._f = sym.factor(np.asarray(As.data, dtype=self.dtype), threads=1)
        except RuntimeError as exc:
            raise SingularShiftError(f"rslab LU: the matrix is singular ({exc})") from exc
        self.nnz = int(self._f.factor_nnz)

    def __reduce__(self):
        raise TypeError("an rslab factorization is a handle of this process; it cannot be pickled")

    def solve(self, b, trans: str = "N"):
        """Solve ``A x = b`` (``trans="N"``) or ``A^T x = b`` (``"T"``); b of shape (N, k) or (N,)."""
        b = np.asarray(b)
        vec = b.ndim == 1
        B = np.asarray(b.reshape(b.shape[0], -1), dtype=self.dtype)
        if trans == "N":
            X = self._f.solve_many(np.ascontiguousarray(B)) if B.shape[1] > 1 else \
                self._f.solve(np.ascontiguousarray(B[:, 0]))[:, None]
        else:
            X = np.column_stack([self._f.solve_transpose(np.ascontiguousarray(B[:, j])) for j in range(B.shape[1])])
        return X[:, 0] if vec else X


#: rslab's LDL^T of a (complex) symmetric S(s) (:class:`RslabLDLT`): METIS ordering, static pivot
#: perturbation (the zero block stops Bunch-Kaufman otherwise), refinement steps per solve and their stop (2026-11-28)
RSLAB_LDLT_SETTINGS = {"ordering": "metis", "preconditioner": 1e-10, "refine": 2, "target": 1e-15}


def rslab_ldlt_symbolic(pattern):
    """``(LdltSymbolic, sel)``: rslab's LDL^T analysis of the pattern's lower triangle (METIS, from the
    pattern's magnitudes) and the positions of the lower triangle's entries in the pattern's CSC data;
    ``None`` when M, D or K is not exactly symmetric (S(s) is then not complex symmetric). Made once per
    pattern. Cost: one METIS ordering (0.25 s at fem_block(4000), 1.7 s at 20000)."""
    def make():
        if not _symmetric_blocks(pattern):
            return None  # kept: not checked again at the next shift
        rslab = _rslab()
        data, ind, ptr = _magnitudes(pattern)
        N = ptr.size - 1
        cols = np.repeat(np.arange(N), np.diff(ptr))
        sel = np.flatnonzero(ind >= cols)
        A = sp.csc_matrix((np.asarray(data, dtype=float), ind.copy(), ptr.copy()), shape=(N, N))
        sym = rslab.analyze(A, path="ldlt", ordering=RSLAB_LDLT_SETTINGS["ordering"], threads=1)
        return sym, sel
    return _stored(pattern, ("rslab-ldlt",), make)


class RslabLDLT:
    r"""rslab's supernodal Bunch-Kaufman :math:`LDL^T` (MIT) of a (complex) symmetric equilibrated saddle matrix.

    :math:`S(s)` is complex symmetric when M, D and K are symmetric (real symmetric at a real shift;
    :math:`A_s = D S D` too, the diagonal scaling being symmetric), so its plain transpose is itself:
    one factor of half the fill of the LU serves ``solve`` with and without ``"T"``.

    - **Pivots.** The zero block of the constraints stops Bunch-Kaufman's 1 x 1 pivots, so pivots
      below ``RSLAB_LDLT_SETTINGS["preconditioner"]`` (1e-10, relative) are perturbed. More
      perturbed pivots than the n2 rows of the constraint block raise
      :class:`~morsuite.errors.SingularShiftError`: the matrix is then (nearly) singular, a
      perturbed factor would hide it, and :func:`rslab_factor` takes the LU, which reports it.
    - **Solves.** Each solve refines against the matrix itself, at most ``refine`` (2) times, until
      rslab's normwise backward error is below ``target`` (1e-15): one step on fem_block, two on
      tcom(20), where one left 2e-12. Measured backward errors 4e-17 to 1.2e-16 at well-damped
      shifts (with pivots perturbed at 1e-12 instead, the factor grew and two steps left 4e-13 to
      8e-11 on tcom(20)); at lightly damped resonances 5e-14 to 6e-12 after the two steps, which
      :class:`~morsuite.linalg.saddle_lu.SaddleLU` refines to its backward-error target with this
      factor (falling back to rslab's LU where that stagnates), as it checks every backend's solves.

    Cost against the LU (docs/design/backends.md, 2026-11-28): a factorization with three solves
    0.61-0.79 of its time at complex shifts of fem_block, a solve about twice its (the refinement
    step). :func:`rslab_factor` takes it at complex shifts only. A real matrix is factored real
    (:class:`~morsuite.linalg.saddle_lu.SaddleLU` solves a complex right-hand side as two real ones).
    """

    def __init__(self, As, pattern, symbolic=None):
        sym, sel = symbolic if symbolic is not None else rslab_ldlt_symbolic(pattern)
        self.dtype = np.complex128 if np.iscomplexobj(As.data) else np.float64
        self.shape = As.shape
        st = RSLAB_LDLT_SETTINGS
        try:
            self._f = sym.factor(np.ascontiguousarray(As.data[sel], dtype=self.dtype), threads=1,
                                 preconditioner=st["preconditioner"])
        except (RuntimeError, ValueError) as exc:
            raise SingularShiftError(f"rslab LDL^T: the factorization failed ({exc})") from exc
        self.nnz = int(self._f.factor_nnz)
        #: pivots perturbed; at most n2 is the zero block's share (300 of 363 on fem_block(4000) at every shift)
        self.perturbed = int(self._f.n_perturbed)
        n2 = int(pattern["shape"][1])
        if self.perturbed > n2:  # a singular (1,1) block, e.g. at a pole: the perturbed factor would hide it
            raise SingularShiftError(f"rslab LDL^T: {self.perturbed} pivots perturbed, more than the n2 = {n2} "
                                     "of the constraint block: the matrix is (nearly) singular")

    def __reduce__(self):
        raise TypeError("an rslab factorization is a handle of this process; it cannot be pickled")

    def solve(self, b, trans: str = "N"):
        """Solve ``A x = b``; ``trans="T"`` is the same solve (A is symmetric); b of shape (N, k) or (N,)."""
        b = np.asarray(b)
        B = np.asarray(b.reshape(b.shape[0], -1), dtype=self.dtype)  # SaddleLU splits complex b of a real factor
        st = RSLAB_LDLT_SETTINGS
        X = np.column_stack([self._f.solve(np.ascontiguousarray(B[:, j]), refine=st["refine"], target=st["target"])
                             for j in range(B.shape[1])])
        return X[:, 0] if b.ndim == 1 else X


def rslab_factor(As, pattern):
    """rslab's factorization of ``As``: :class:`RslabLDLT` at a complex shift where M, D and K are
    symmetric (:func:`rslab_ldlt_symbolic`) and the values of ``As`` are too, else :class:`RslabLU`.
    The values' symmetry is checked exactly (the CSR order of the data equals the CSC order), O(nnz).

    Real shifts keep the LU: there the LDL^T's factorization gains less (0.74-0.89 of the LU's time
    with three solves, two runs) and its solves cost about twice the LU's, so a solve-heavy caller lost:
    modal truncation's shift-invert Lanczos on fem_block(20000) took 20.5 s against 13.0 s
    (docs/design/backends.md, 2026-11-28)."""
    if np.iscomplexobj(As.data):
        ldlt = rslab_ldlt_symbolic(pattern)
        if ldlt is not None and np.array_equal(As.data[pattern["_csr_perm"]], As.data):
            try:
                return RslabLDLT(As, pattern, ldlt)
            except SingularShiftError:  # more perturbed pivots than the constraint block explains: the LU decides
                pass
    return RslabLU(As, pattern)
