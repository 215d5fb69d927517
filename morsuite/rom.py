r"""Reduced models: second-order :math:`(\hat M, \hat D, \hat K, \hat F, \hat L)` and
first-order descriptor :math:`(E, A, B, C, D)`.

Orders: a :class:`SecondOrderROM` of order ``r`` has ``r x r`` matrices and
``2 r`` first-order states; ``rom.order`` is r, ``rom.states`` the number of
first-order states. Tables and plots always say which one they use.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.linalg as sla

from .errors import FileFormatError, InputError, ShapeError
from .utils import atomic_path

__all__ = ["SecondOrderROM", "FirstOrderROM", "load_rom"]


def _mat(name, X, shape=None):
    X = np.asarray(X)
    if X.ndim == 1 and shape is not None:
        X = X.reshape(shape)
    if X.ndim != 2:
        raise ShapeError(f"matrix {name} must be 2-D; got shape {X.shape}")
    if np.iscomplexobj(X):
        if np.any(X.imag != 0):
            raise InputError(f"matrix {name} is complex; reduced models are real")
        X = X.real
    X = np.array(X, dtype=float)
    if not np.all(np.isfinite(X)):
        raise InputError(f"matrix {name} has non-finite entries")
    return X


def _omega(omega):
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    if w.ndim != 1:
        raise InputError(f"omega must be 1-D; got shape {w.shape}")
    return w


def _finite_eigs(A, E):
    lam = sla.eigvals(A, E)
    return lam[np.isfinite(lam)]


class _ROMBase:
    kind = "base"
    #: the JSON sidecar of a model read by :func:`morsuite.romfiles.load_rom` (None otherwise)
    provenance = None

    def freqresp(self, omega) -> np.ndarray:
        """Response at ``s = 1j * omega``: complex (len(omega), p, m)."""
        return self.transfer_many(1j * _omega(omega))

    def transfer(self, s) -> np.ndarray:
        """Transfer function at one complex ``s``: (p, m)."""
        return self.transfer_many(np.array([complex(s)]))[0]

    def is_stable(self, tol: float = 0.0) -> bool:
        """True if every finite pole has real part ``< -tol * max(1, |pole|)``."""
        lam = self.poles()
        return bool(np.all(lam.real < -tol * np.maximum(1.0, np.abs(lam))))

    def to_control(self):
        """The python-control :class:`control.StateSpace` (E^-1 applied to A and B)."""
        import control

        E, A, B, C, D = self._first_order_arrays()
        return control.ss(np.linalg.solve(E, A), np.linalg.solve(E, B), C, D)

    def save(self, path) -> Path:
        """Write the matrices alone to one ``.npz`` or ``.mat`` file (chosen by the extension), atomically.

        The file holds ``kind`` and the matrices under their own names
        (:mod:`morsuite.romfiles` lists them); no provenance sidecar is written:
        :func:`morsuite.romfiles.save_rom` writes both formats and the sidecar, and is what the
        command line uses. Cost: writing ``r^2`` numbers.
        """
        path = Path(path)
        arrays = {k: getattr(self, k) for k in self._fields}
        if path.suffix == ".npz":
            arrays["kind"] = np.array(self.kind)
            with atomic_path(path, suffix=".npz") as tmp:
                with open(tmp, "wb") as fh:
                    np.savez(fh, **arrays)
        elif path.suffix == ".mat":
            import scipy.io as sio
            # MATLAB v5, uncompressed; ``kind`` a char row vector (a MATLAB string), the matrices doubles
            with atomic_path(path, suffix=".mat") as tmp:
                sio.savemat(tmp, {**arrays, "kind": self.kind}, format="5", do_compression=False)
        else:
            raise InputError(f"path {str(path)!r}: extension must be .npz or .mat")
        return path


def _lift(basis, r):
    """A reduced model's position lift checked: None, or a real 2-D array with ``r`` columns."""
    if basis is None:
        return None
    basis = np.asarray(basis)
    if basis.ndim != 2 or basis.shape[1] != r:
        raise ShapeError(f"basis has shape {basis.shape}; expected (n1, {r})")
    if np.iscomplexobj(basis):
        if np.any(basis.imag != 0):
            raise InputError("basis is complex; the lift of a real reduced model is real")
        basis = basis.real
    return basis


class SecondOrderROM(_ROMBase):
    r"""Dense second-order model :math:`\hat M \ddot x + \hat D \dot x + \hat K x = \hat F u`, :math:`y = \hat L x`.

    ``basis``, optional: the n1 x r matrix V of a projection-based reduced model (its
    positions lift to the full model's as :math:`x \approx Vq`; used for mode-shape
    comparisons such as :func:`morsuite.analysis.modes.mac`). None (default) where the
    reducer does not give it; it is not written by :meth:`save`.
    """

    kind = "second-order"
    _fields = ("M", "D", "K", "F", "L")

    def __init__(self, M, D, K, F, L, *, basis=None):
        self.M = _mat("M", M)
        r = self.M.shape[0]
        if self.M.shape != (r, r):
            raise ShapeError(f"matrix M must be square; got {self.M.shape}")
        self.D, self.K = _mat("D", D), _mat("K", K)
        for nm, X in (("D", self.D), ("K", self.K)):
            if X.shape != (r, r):
                raise ShapeError(f"matrix {nm} has shape {X.shape}; expected ({r}, {r})")
        self.F = _mat("F", F, (r, 1))
        self.L = _mat("L", L, (1, r))
        if self.F.shape[0] != r:
            raise ShapeError(f"matrix F has {self.F.shape[0]} rows; expected {r}")
        if self.L.shape[1] != r:
            raise ShapeError(f"matrix L has {self.L.shape[1]} columns; expected {r}")
        #: the lift V (n1 x r) of a projection-based model, or None
        self.basis = _lift(basis, r)

    @property
    def order(self) -> int:
        """r, the dimension of the second-order matrices."""
        return self.M.shape[0]

    @property
    def states(self) -> int:
        """First-order states, 2r."""
        return 2 * self.order

    @property
    def m(self):
        """Number of inputs (columns of F)."""
        return self.F.shape[1]

    @property
    def p(self):
        """Number of outputs (rows of L)."""
        return self.L.shape[0]

    def __repr__(self):
        return f"SecondOrderROM(r={self.order}, states={self.states}, m={self.m}, p={self.p})"

    def transfer_many(self, s) -> np.ndarray:
        r""":math:`T_r(s_k) = \hat L (s_k^2 \hat M + s_k \hat D + \hat K)^{-1} \hat F` at every point of ``s``:
        complex (len(s), p, m); one dense r x r solve per point."""
        s = np.asarray(s, dtype=complex).reshape(-1)
        P = s[:, None, None] ** 2 * self.M + s[:, None, None] * self.D + self.K
        X = np.linalg.solve(P, np.broadcast_to(self.F, (s.size,) + self.F.shape))
        return self.L @ X

    def transfer_derivative(self, s) -> np.ndarray:
        """:math:`T_r'(s) = -\\hat L P^{-1} (2 s \\hat M + \\hat D) P^{-1} \\hat F`."""
        s = complex(s)
        P = s * s * self.M + s * self.D + self.K
        X = np.linalg.solve(P, self.F)
        return -self.L @ np.linalg.solve(P, (2 * s * self.M + self.D) @ X)

    def first_order(self):
        """(E, A, B, C) with E = blkdiag(I, M), A = [[0, I], [-K, -D]], B = [0; F], C = [L, 0]."""
        r = self.order
        I, Z = np.eye(r), np.zeros((r, r))
        E = np.block([[I, Z], [Z, self.M]])
        A = np.block([[Z, I], [-self.K, -self.D]])
        B = np.vstack([np.zeros((r, self.m)), self.F])
        C = np.hstack([self.L, np.zeros((self.p, r))])
        return E, A, B, C

    def _first_order_arrays(self):
        E, A, B, C = self.first_order()
        return E, A, B, C, np.zeros((self.p, self.m))

    def to_first_order(self) -> "FirstOrderROM":
        """The same model as a :class:`FirstOrderROM` with the realization of :meth:`first_order`."""
        E, A, B, C = self.first_order()
        return FirstOrderROM(E, A, B, C)

    def poles(self) -> np.ndarray:
        """The 2r eigenvalues of the quadratic pencil :math:`\\lambda^2 \\hat M + \\lambda \\hat D + \\hat K`."""
        return self.eig(vectors=False)

    def eig(self, vectors: bool = True):
        r"""Eigenvalues (and right eigenvectors of the first-order pencil (A, E)).

        :math:`\lambda = g\mu` with :math:`g = \sqrt{\|K\|/\|M\|}`: QZ runs on the
        balanced pencil :math:`(g^2 M, g D, K) / \|K\|`; with M ~ 1e-7 and K ~ 1e9 the
        raw pencil made LAPACK's ggev fail (stress suite, K6). Eigenvectors are
        returned in the coordinates of :meth:`first_order` (``[x; lambda x]``),
        infinite eigenvalues dropped.
        """
        nm, nk = np.linalg.norm(self.M, 1), np.linalg.norm(self.K, 1)
        g = np.sqrt(nk / nm) if nm > 0 and nk > 0 else 1.0
        # and the pencil divided by ||K|| (= g^2 ||M||): E = blkdiag(I, M / ||M||) stays of norm 1; with
        # (g^2 M, g D, K) alone, ||M|| = 1, ||K|| = 5e16 made E's blocks 1 and 5e16 and QZ returned a pole
        # in the right half-plane for an SPD model (stress suite, modal on random units 1e-6 / 1e9)
        c = 1.0 / nk if nk > 0 else 1.0
        scaled = SecondOrderROM(c * g * g * self.M, c * g * self.D, c * self.K, self.F, self.L)
        E, A, _, _ = scaled.first_order()
        if not vectors:
            return g * _finite_eigs(A, E)
        mu, Z = sla.eig(A, E)
        ok = np.isfinite(mu)
        Z = Z[:, ok]
        Z[self.order:] *= g  # [x; mu x] -> [x; lambda x]
        return g * mu[ok], Z


class FirstOrderROM(_ROMBase):
    r"""Dense descriptor model :math:`E \dot x = A x + B u`, :math:`y = C x + D u`.

    ``basis``, optional: the n1 x n position lift :math:`V_1` of a projection-based reduced
    model of the first-order realization (the full model's positions are :math:`x \approx V_1
    \hat x`; irka-fo, first-order BT). Used for mode-shape comparisons
    (:func:`morsuite.analysis.modes.rom_modes`); None (default) otherwise; not written by
    :meth:`save`.
    """

    kind = "first-order"
    _fields = ("E", "A", "B", "C", "D")

    def __init__(self, E, A, B, C, D=None, *, basis=None):
        self.A = _mat("A", A)
        n = self.A.shape[0]
        if self.A.shape != (n, n):
            raise ShapeError(f"matrix A must be square; got {self.A.shape}")
        self.E = np.eye(n) if E is None else _mat("E", E)
        if self.E.shape != (n, n):
            raise ShapeError(f"matrix E has shape {self.E.shape}; expected ({n}, {n})")
        self.B = _mat("B", B, (n, 1))
        self.C = _mat("C", C, (1, n))
        if self.B.shape[0] != n:
            raise ShapeError(f"matrix B has {self.B.shape[0]} rows; expected {n}")
        if self.C.shape[1] != n:
            raise ShapeError(f"matrix C has {self.C.shape[1]} columns; expected {n}")
        self.D = np.zeros((self.C.shape[0], self.B.shape[1])) if D is None else _mat("D", D)
        if self.D.shape != (self.C.shape[0], self.B.shape[1]):
            raise ShapeError(f"matrix D has shape {self.D.shape}; expected {(self.C.shape[0], self.B.shape[1])}")
        #: the position lift V_1 (n1 x n) of a projection-based model, or None
        self.basis = _lift(basis, n)

    @property
    def order(self) -> int:
        """Number of states (the dimension of A)."""
        return self.A.shape[0]

    @property
    def states(self) -> int:
        """Number of states, the same as :attr:`order`."""
        return self.order

    @property
    def m(self):
        """Number of inputs (columns of B)."""
        return self.B.shape[1]

    @property
    def p(self):
        """Number of outputs (rows of C)."""
        return self.C.shape[0]

    def __repr__(self):
        return f"FirstOrderROM(states={self.states}, m={self.m}, p={self.p})"

    def transfer_many(self, s) -> np.ndarray:
        r""":math:`T_r(s_k) = C (s_k E - A)^{-1} B + D` at every point of ``s``: complex (len(s), p, m);
        one dense solve per point."""
        s = np.asarray(s, dtype=complex).reshape(-1)
        P = s[:, None, None] * self.E - self.A
        X = np.linalg.solve(P, np.broadcast_to(self.B, (s.size,) + self.B.shape))
        return self.C @ X + self.D

    def transfer_derivative(self, s) -> np.ndarray:
        r""":math:`T_r'(s) = -C (sE - A)^{-1} E (sE - A)^{-1} B`."""
        s = complex(s)
        P = s * self.E - self.A
        return -self.C @ np.linalg.solve(P, self.E @ np.linalg.solve(P, self.B))

    def _first_order_arrays(self):
        return self.E, self.A, self.B, self.C, self.D

    def to_first_order(self) -> "FirstOrderROM":
        """This model itself."""
        return self

    def poles(self) -> np.ndarray:
        """Finite generalized eigenvalues of the pencil (A, E)."""
        return _finite_eigs(self.A, self.E)


def _text(x):
    """A string stored as a 0-d (.npz) or 1-element (.mat char array) array, else None."""
    a = np.asarray(x)
    if a.dtype.kind not in "US" or a.size != 1:
        return None
    return str(a.ravel()[0])


def _read_arrays(path: Path) -> dict:
    """The named arrays of a .npz or .mat file; FileFormatError naming the file when it cannot be read."""
    where = f"ROM file {str(path)!r}"
    if not path.is_file():
        raise FileFormatError(f"{where} does not exist")
    if path.suffix not in (".npz", ".mat"):
        raise FileFormatError(f"{where}: extension must be .npz or .mat")
    try:
        if path.suffix == ".npz":
            with np.load(path, allow_pickle=False) as z:
                return {k: z[k] for k in z.files}
        import scipy.io as sio
        return {k: v for k, v in sio.loadmat(str(path)).items() if not k.startswith("__")}
    except Exception as exc:  # a truncated zip, a pickled object, an HDF5 (v7.3) or garbled .mat ...
        kind = "NumPy .npz archive" if path.suffix == ".npz" else "MATLAB v5 .mat file"
        raise FileFormatError(f"{where} is not a readable {kind} ({type(exc).__name__}: {exc})") from exc


def load_rom(path):
    """Read one file written by ``rom.save`` or :func:`morsuite.romfiles.save_rom` (.npz or .mat).

    The file alone: :func:`morsuite.load_rom` (:func:`morsuite.romfiles.load_rom`) also checks
    the provenance sidecar and attaches it. Values come back bit for bit.

    Raises
    ------
    FileFormatError
        Naming the file: it does not exist, has another extension, cannot be read, lacks
        ``kind`` or a matrix, or its matrices do not make a reduced model (the reason given).
    """
    path = Path(path)
    where = f"ROM file {str(path)!r}"
    data = _read_arrays(path)
    kind = _text(data["kind"]) if "kind" in data else ""
    cls = {"second-order": SecondOrderROM, "first-order": FirstOrderROM}.get(kind)
    if cls is None:
        raise FileFormatError(f"{where}: entry 'kind' missing or unknown ({kind!r}); expected 'second-order' "
                              "or 'first-order'")
    missing = [k for k in cls._fields if k not in data]
    if missing:
        raise FileFormatError(f"{where}: missing key {', '.join(missing)} of a {kind} model")
    bad = [k for k in cls._fields if np.asarray(data[k]).dtype.kind not in "biufc"]
    if bad:
        raise FileFormatError(f"{where}: matrix {', '.join(bad)} is not real numeric data "
                              f"(dtype {np.asarray(data[bad[0]]).dtype})")
    try:
        return cls(*(data[k] for k in cls._fields))
    except InputError as exc:
        raise FileFormatError(f"{where}: {exc}") from exc
