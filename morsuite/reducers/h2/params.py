r"""Parametrisations of second-order reduced models for the H2 descent (``so-h2``).

Both keep :math:`\hat M = I`, which loses no model with an invertible
:math:`\hat M` (:math:`\hat M^{-1}` applied to the equation; for a symmetric
positive definite :math:`\hat M = L_ML_M^T`, the congruence with :math:`L_M^{-1}`
keeps :math:`\hat D` and :math:`\hat K` symmetric).

``"general"`` (:class:`General`)
    :math:`\theta = (\hat K, \hat D, \hat F, \hat L)`, every entry free:
    :math:`2r^2 + r(m + p)` variables. Stability is not built in: the descent
    rejects steps that leave the stable set (the objective is infinite there).
``"passive"`` (:class:`Passive`)
    :math:`\hat K = \mathrm{diag}(e^{2u_i})`, :math:`\hat D = L_DL_D^T` with
    :math:`L_D` lower triangular, :math:`\hat F`, :math:`\hat L` free:
    :math:`r + r(r+1)/2 + r(m+p)` variables. Symmetric positive definite
    :math:`\hat K` and (for nonsingular :math:`L_D`) :math:`\hat D`, like the
    model: for an eigenpair, :math:`\lambda^2 + \lambda x^H\hat Dx + x^H\hat Kx = 0`
    (:math:`\|x\| = 1`) has both roots in the open left half-plane, so every
    iterate is stable by construction. A diagonal :math:`\hat K` loses nothing:
    an orthogonal congruence diagonalises a symmetric one. Only a model with
    symmetric :math:`\hat M, \hat D, \hat K` (``bt`` with ``form="fv"``) can start it.

Each maps :math:`\theta` to :math:`(\hat K, \hat D, \hat F, \hat L)`, the gradient in
those matrices to the gradient in :math:`\theta` (chain rule), and the Gauss-Newton
diagonal likewise (its cross terms dropped: a preconditioner).
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ...rom import SecondOrderROM

__all__ = ["General", "Passive", "PARAMETRISATIONS"]


class General:
    """:math:`\\theta = (\\hat K, \\hat D, \\hat F, \\hat L)` with :math:`\\hat M = I`."""

    name = "general"

    def __init__(self, r: int, m: int, p: int):
        self.r, self.m, self.p = r, m, p
        self.sizes = (r * r, r * r, r * m, p * r)

    @property
    def size(self) -> int:
        """Number of real parameters in :math:`\\theta`."""
        return sum(self.sizes)

    @staticmethod
    def accepts(rom) -> bool:
        """Whether ``rom`` can be written in this parametrisation (its :math:`\\hat M` invertible: cond < 1e12)."""
        return np.linalg.cond(rom.M) < 1e12

    def from_rom(self, rom: SecondOrderROM) -> np.ndarray:
        """θ of ``rom`` (:math:`\\hat M^{-1}` applied)."""
        if not self.accepts(rom):
            raise InputError("the reduced mass matrix is singular to working precision")
        lu = np.linalg.solve
        return np.concatenate([lu(rom.M, rom.K).ravel(), lu(rom.M, rom.D).ravel(), lu(rom.M, rom.F).ravel(),
                               rom.L.ravel()])

    def _split(self, v):
        out, i = [], 0
        for n in self.sizes:
            out.append(v[i:i + n])
            i += n
        return out

    def matrices(self, theta):
        """:math:`(\\hat K, \\hat D, \\hat F, \\hat L)` of :math:`\\theta` (:math:`\\hat M = I`)."""
        k, d, f, l_ = self._split(theta)
        r, m, p = self.r, self.m, self.p
        return k.reshape(r, r), d.reshape(r, r), f.reshape(r, m), l_.reshape(p, r)

    def gradient(self, theta, grads) -> np.ndarray:
        """The gradient in :math:`\\theta` from the gradients ``grads`` in :math:`(\\hat K, \\hat D, \\hat F, \\hat L)`."""
        return np.concatenate([g.ravel() for g in grads])

    def gauss_newton(self, theta, diag) -> np.ndarray:
        """The Gauss-Newton diagonal in :math:`\\theta` from the diagonals ``diag`` in the matrices (chain rule)."""
        return np.concatenate([h.ravel() for h in diag])

    def rom(self, theta) -> SecondOrderROM:
        """The second-order reduced model of :math:`\\theta`."""
        K, D, F, L = self.matrices(theta)
        return SecondOrderROM(np.eye(self.r), D, K, F, L)


class Passive(General):
    """:math:`\\hat K = \\mathrm{diag}(e^{2u})`, :math:`\\hat D = L_DL_D^T`, :math:`\\hat F`, :math:`\\hat L`."""

    name = "passive"

    def __init__(self, r: int, m: int, p: int):
        super().__init__(r, m, p)
        self._tril = np.tril_indices(r)
        self.sizes = (r, self._tril[0].size, r * m, p * r)

    @staticmethod
    def accepts(rom) -> bool:
        """Whether ``rom`` has symmetric positive definite :math:`\\hat M, \\hat D, \\hat K` (needed for this parametrisation)."""
        for X in (rom.M, rom.D, rom.K):
            if not np.allclose(X, X.T, rtol=1e-10, atol=1e-13 * np.abs(X).max()):
                return False
        try:
            for X in (rom.M, rom.K, rom.D):
                np.linalg.cholesky(0.5 * (X + X.T))
        except np.linalg.LinAlgError:
            return False
        return True

    def from_rom(self, rom: SecondOrderROM) -> np.ndarray:
        """θ of a ``rom`` with symmetric positive definite M, D, K (congruence to M = I, K diagonal)."""
        if not self.accepts(rom):
            raise InputError("the passive parametrisation needs symmetric positive definite M, D and K "
                             "(bt with form='fv' gives them)")
        sym = lambda X: 0.5 * (X + X.T)  # noqa: E731
        Lm = np.linalg.cholesky(sym(rom.M))
        inv = lambda X: np.linalg.solve(Lm, X)  # noqa: E731
        Kt = sym(inv(inv(sym(rom.K)).T))
        w, Q = np.linalg.eigh(Kt)
        Dt = sym(Q.T @ inv(inv(sym(rom.D)).T) @ Q)
        Ld = np.linalg.cholesky(Dt)
        F = Q.T @ inv(rom.F)
        L = np.linalg.solve(Lm, rom.L.T).T @ Q     # L Lm^{-T} Q
        return np.concatenate([0.5 * np.log(w), Ld[self._tril], F.ravel(), L.ravel()])

    def _factor(self, ld):
        Ld = np.zeros((self.r, self.r))
        Ld[self._tril] = ld
        return Ld

    def matrices(self, theta):
        """:math:`(\\mathrm{diag}(e^{2u}), L_DL_D^T, \\hat F, \\hat L)` of :math:`\\theta`."""
        u, ld, f, l_ = self._split(theta)
        Ld = self._factor(ld)
        return np.diag(np.exp(2.0 * u)), Ld @ Ld.T, f.reshape(self.r, self.m), l_.reshape(self.p, self.r)

    def gradient(self, theta, grads) -> np.ndarray:
        """The gradient in :math:`\\theta = (u, L_D, \\hat F, \\hat L)` by the chain rule through
        :math:`\\hat K = \\mathrm{diag}(e^{2u})` and :math:`\\hat D = L_DL_D^T`."""
        gK, gD, gF, gL = grads
        u, ld, _, _ = self._split(theta)
        Ld = self._factor(ld)
        gu = 2.0 * np.exp(2.0 * u) * np.diag(gK)
        gLd = (gD + gD.T) @ Ld
        return np.concatenate([gu, gLd[self._tril], gF.ravel(), gL.ravel()])

    def gauss_newton(self, theta, diag) -> np.ndarray:
        """The Gauss-Newton diagonal in :math:`\\theta` (chain rule, cross terms dropped)."""
        HK, HD, HF, HL = diag
        u, ld, _, _ = self._split(theta)
        Ld = self._factor(ld)
        hu = (2.0 * np.exp(2.0 * u)) ** 2 * np.diag(HK)
        hLd = (HD + HD.T) @ (Ld * Ld)
        return np.concatenate([hu, hLd[self._tril], HF.ravel(), HL.ravel()])


PARAMETRISATIONS = {"general": General, "passive": Passive}
