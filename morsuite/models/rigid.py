r"""Free-floating structures: rigid-body modes, the flexible part, and the rigid part added back.

A model is *free floating* when its stiffness is singular on the constraint manifold:
:math:`K\varphi + G^T\mu = 0`, :math:`G\varphi = 0` has solutions :math:`\varphi \ne 0`
(rigid-body modes of satellites, vehicles, free-free test articles; also mechanisms).
Then :math:`S(0)` is singular, :math:`T(s)` has a pole at :math:`s = 0`, and
:math:`T \notin \mathcal H_2`: every method whose solves, Gramians or norms touch
:math:`s = 0` fails ("the shift is a pole").

**Detection** (:func:`rigid_body_modes`, cached in ``model.cache``). The undamped
constrained eigenproblem :math:`K\varphi + G^T\mu = \lambda M\varphi`, :math:`G\varphi = 0` is
solved for its lowest modes by shift-invert Lanczos with one sparse LU of the bordered
:math:`K - \sigma M` at a shift **below** zero, :math:`\sigma = -10^{-6}\rho`,
:math:`\rho = \max_i K_{ii}/M_{ii}` (an estimate of the largest eigenvalue), where the
matrix is nonsingular whatever the rigid modes
(:func:`morsuite.linalg.eigen.constrained_modes`). Modes with
:math:`|\lambda| \le` ``rtol`` :math:`\rho` are rigid; k doubles from 8 while every mode
found is rigid. A symmetric K with positive diagonal that is diagonally dominant, strictly
in at least one row of each connected component of its graph, is positive definite: then
there is no rigid mode and nothing is factored (the chains ``dsms`` and ``tcom``).
A detection that raises (``info["status"]`` "failed": the model is treated as having no
rigid mode) or that ARPACK converges only in part ("partial": rigid modes may be missing)
is never silent: a :class:`~morsuite.errors.ConvergenceWarning`, ``info["reason"]``, and
every reducer on the model records it (``info["rigid_modes"]``, status ``detection-failed``,
:mod:`morsuite.reducers.outcome`).

**Deflation** (:func:`flexible_part`). With :math:`\Phi` (n1 x k) the rigid modes,
M-orthonormal, and any basis :math:`Z_f` of the M-orthogonal complement of
:math:`\operatorname{span}\Phi` in :math:`\ker G`, the model's matrices on
:math:`[\Phi, Z_f]` are block diagonal: :math:`\Phi^TMZ_f = 0` by construction,
:math:`\Phi^TKZ_f = -\mu^TGZ_f = 0`, and :math:`\Phi^TDZ_f = 0` under the damping
assumption below. Hence

.. math::

    T(s) = \underbrace{L\Phi\,(s^2I + sD_\Phi)^{-1}\Phi^TF}_{T_\text{rig}(s)}
         + \underbrace{LZ_f(Z_f^T(s^2M + sD + K)Z_f)^{-1}Z_f^TF}_{T_\text{flex}(s)},
    \qquad D_\Phi = \Phi^TD\Phi ,

and :math:`T_\text{flex}` is the transfer function of the same model with the k
constraint rows :math:`\Phi^TM x = 0` appended to G (a rank-k change of the border: no
:math:`\Pi`, no n1 x n1 matrix; the k rows are dense, which a sparse LU orders last).
:math:`T_\text{flex}` is stable (damped) and in :math:`\mathcal H_2`; every reducer
reduces it, and :func:`with_rigid` adds :math:`T_\text{rig}` back exactly as a
second-order block with :math:`\hat M = I`, :math:`\hat K = 0`, :math:`\hat D = D_\Phi`,
:math:`\hat F = \Phi^TF`, :math:`\hat L = L\Phi` (the wrapper of
:class:`morsuite.reducers.Reducer`). The error :math:`T - T_r = T_\text{flex} -
T_{r,\text{flex}}` is in :math:`\mathcal H_2`; :func:`split` gives the norms the two
flexible parts.

**Damping assumption.** Exact deflation needs :math:`Z_f^TD\Phi = 0`, i.e.
:math:`D\Phi \in M\Phi\,\mathbb R^{k\times k} + \operatorname{range}G^T`: true for
Rayleigh damping :math:`D = \alpha M + \beta K` (:math:`D_\Phi = \alpha I`) and for any D
that annihilates the rigid modes. It is measured (``coupling``, one solve per mode with
the detection LU) and :func:`flexible_part` refuses a model above ``coupling_tol``.

Cost: none for a diagonally dominant K; else one sparse LU of order n1 + n2 and the
Lanczos solves (about 3k to 5k for k = 8 modes), once per model. The flexible part's LUs
carry k dense border rows (O(k n1) more fill). Design note: ``docs/design/free_floating.md``.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
import scipy.sparse.linalg as spla

from ..errors import ConvergenceWarning, InputError, ModelError, MorsuiteError

__all__ = ["RigidModes", "rigid_body_modes", "flexible_part", "with_rigid", "split", "RTOL", "COUPLING_TOL",
           "DAMPING_UNIT"]

#: eigenvalues with absolute value at most RTOL * rho (rho about the largest eigenvalue) are rigid-body modes
RTOL = 1e-10
#: largest relative damping coupling between rigid and flexible modes that deflation accepts
#: (rounding gives 1e-16 and below; dsms(200) with its end dampers doubled, 6e-6)
COUPLING_TOL = 1e-10
#: D_Phi counts as zero (``damped`` False) below DAMPING_UNIT * sqrt(n1) * eps * ``max(abs(Phi).T @ abs(D) @
#: abs(Phi))``, the rounding of the product (with D Phi = 0 exactly, the shapes' errors enter squared):
#: dsms(40, free=True) gives 4e-33 against a level of 3e-15
DAMPING_UNIT = 10.0
#: the detection shift is -SHIFT * rho
SHIFT = 1e-6
#: probe this many modes first (six rigid-body modes of a 3D body, and one more)
PROBE = 8
_CACHE_KEY = "rigid_modes"


@dataclass
class RigidModes:
    r"""The rigid-body (zero-energy) modes of a constrained model.

    Attributes
    ----------
    shapes : ndarray (n1, k)
        :math:`\Phi`, M-orthonormal (:math:`\Phi^TM\Phi = I`), :math:`G\Phi = 0`,
        :math:`K\Phi \in \operatorname{range}G^T` to the solves' accuracy.
    eigenvalues : ndarray (k,)
        Their computed :math:`\lambda` (zero up to rounding).
    damping : ndarray (k, k)
        :math:`D_\Phi = \Phi^TD\Phi`.
    coupling : float
        Relative size of the damping coupling of rigid and flexible modes (0: none; module
        docstring).
    lowest_flexible : float
        Angular frequency (rad/s) of the lowest flexible mode found (nan if none was).
    info : dict
        Plain data: ``method`` ("diagonal-dominance", "lanczos", "dense", or "failed" with
        ``error``: the detection raised, k = 0), ``status`` ("ok"; "partial": ARPACK converged
        only some of the modes asked for, rigid modes may be missing; "failed") and ``reason``
        (None when "ok"; else the sentence of the :class:`ConvergenceWarning` issued), ``sigma``,
        ``rho``, ``rtol``, ``lu_count``, ``solves``, ``time_s``, ``max_rigid_eigenvalue``
        (largest :math:`|\lambda|/\rho` of the rigid modes: rounding, about 1e-16),
        ``damping_tol`` (the rounding level of :math:`D_\Phi`: :data:`DAMPING_UNIT`
        :math:`\sqrt{n_1}\,\varepsilon\,\max_{ij}(|\Phi|^T|D||\Phi|)_{ij}`).
    """

    shapes: np.ndarray
    eigenvalues: np.ndarray
    damping: np.ndarray
    coupling: float = 0.0
    lowest_flexible: float = float("nan")
    info: dict = field(default_factory=dict)

    @property
    def k(self) -> int:
        """Number of rigid-body modes."""
        return int(self.shapes.shape[1])

    @property
    def damped(self) -> bool:
        r"""Whether :math:`D_\Phi` is nonzero beyond its rounding: some :math:`|(D_\Phi)_{ij}|` above
        ``damping_tol`` (``info``; 0 when there are no rigid modes)."""
        return bool(self.k and np.max(np.abs(self.damping)) > self.info.get("damping_tol", 0.0))

    def summary(self) -> dict:
        """Plain data for ``info`` and reports: ``count``, ``lowest_flexible_rad_s``, ``coupling``,
        ``damped`` (:attr:`damped`: D_Phi nonzero beyond ``damping_tol``) and the detection's ``info``
        (``status`` "ok", "partial" or "failed", with its ``reason``)."""
        return {"count": self.k, "lowest_flexible_rad_s": _plain(self.lowest_flexible),
                "coupling": float(self.coupling), "damped": self.damped, **self.info}

    def line(self, name: str = "model") -> str:
        """One line saying what was found, as ``morsuite info`` and ``compare`` print it."""
        if self.info.get("status") in ("partial", "failed"):
            return (f"{name}: rigid-body detection {self.info['status']} ({self.info.get('reason')}); "
                    f"treated as having {self.k} rigid-body mode{'s' if self.k != 1 else ''}")
        if not self.k:
            return f"{name}: no rigid-body modes (K is nonsingular on ker G; {self.info.get('method')})"
        low = "" if not np.isfinite(self.lowest_flexible) else f", lowest flexible mode {self.lowest_flexible:.4g} rad/s"
        return (f"{name}: {self.k} rigid-body mode{'s' if self.k > 1 else ''} (K singular on ker G{low}): "
                "modal keeps them; the other methods reduce the flexible part and add them back exactly")


def _plain(x):
    return None if not np.isfinite(x) else float(x)


def _scale(model) -> float:
    """rho = max_i K_ii / M_ii over M_ii > 0: the order of the largest eigenvalue."""
    dk, dm = model.K.diagonal(), model.M.diagonal()
    ok = dm > 0
    rho = float(np.max(np.abs(dk[ok]) / dm[ok])) if np.any(ok) else 0.0
    return rho if rho > 0 and np.isfinite(rho) else 1.0


def _positive_definite_by_dominance(K) -> bool:
    """K symmetric, positive diagonal, weakly diagonally dominant, strictly in a row of every
    connected component of its graph (irreducibly dominant): then K is positive definite."""
    K = sp.csr_matrix(K)
    if K.shape[0] == 0 or abs(K - K.T).max() > 1e-14 * abs(K).max():
        return False
    d = K.diagonal()
    off = np.asarray(abs(K).sum(axis=1)).ravel() - np.abs(d)
    if np.any(d <= 0) or np.any(d < off * (1 - 1e-14)):
        return False
    strict = d > off * (1 + 1e-12)
    n_comp, labels = csgraph.connected_components(K, directed=False)
    return bool(np.all(np.bincount(labels[strict], minlength=n_comp) > 0))


def rigid_body_modes(model, *, rtol: float = RTOL, refresh: bool = False) -> RigidModes:
    r"""The rigid-body modes of ``model`` (module docstring), computed once and cached.

    Parameters
    ----------
    model : Index3Model
    rtol : float
        Eigenvalues :math:`|\lambda| \le` ``rtol`` :math:`\rho` count as rigid (default
        :data:`RTOL` = 1e-10; :math:`\rho = \max_i K_{ii}/M_{ii}`). Rounding puts a rigid
        mode's :math:`\lambda` near :math:`10^{-16}\rho`; a flexible one below the tolerance
        would need a chain of about :math:`3\cdot 10^5` masses.
    refresh : bool
        Recompute even if cached.

    Returns
    -------
    RigidModes
        ``k = 0`` for a model without rigid-body modes. Stored in
        ``model.cache["rigid_modes"]`` (with ``rtol``).

    Raises
    ------
    InputError
        If ``rtol`` is not in (0, 1).

    Cost: none when K is positive definite by diagonal dominance; else one sparse LU of
    the bordered :math:`K - \sigma M` (``info["lu_count"]``) and the Lanczos solves for 8
    modes (16, 32, ... while all found are rigid), and O(n1 k) for the damping coupling.
    """
    if not (isinstance(rtol, (int, float)) and 0 < rtol < 1):
        raise InputError(f"rtol must be a float in (0, 1); got {rtol!r}")
    cached = model.cache.get(_CACHE_KEY)
    if cached is not None and not refresh and cached.info.get("rtol") == rtol:
        return cached
    t0 = time.perf_counter()
    rho = _scale(model)
    n1, limit = model.n1, model.order - 1
    info = {"rtol": float(rtol), "rho": rho, "sigma": None, "lu_count": 0, "solves": 0, "status": "ok",
            "reason": None}
    lu = None
    if _positive_definite_by_dominance(model.K):
        info["method"] = "diagonal-dominance"
        lam, Phi = np.zeros(0), np.zeros((n1, 0))
        low = float("nan")
    elif limit <= PROBE:
        from ..linalg.eigen import null_space_modes

        info["method"] = "dense"
        dense = null_space_modes(model)
        lam, Phi = dense.eigenvalues, dense.shapes
    else:
        from ..linalg.eigen import constrained_modes

        info["method"] = "lanczos"
        sigma = -SHIFT * rho
        solver = model.new_solver(cache_size=1)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ConvergenceWarning)  # a partial run is said below, once
                lu = solver.factor(coeffs=(-sigma, 0.0, 1.0))
                kk = min(PROBE, limit)
                while True:
                    res = constrained_modes(model, k=kk, sigma=sigma, factorization=lu)
                    info["solves"] += res.info["solves"]
                    if (res.info["status"] != "converged" or kk >= limit
                            or np.any(np.abs(res.eigenvalues) > rtol * rho)):
                        break
                    kk = min(limit, 2 * kk)
            lam, Phi = res.eigenvalues, res.shapes
            info["method"] = "lanczos" if res.info["method"] == "lanczos" else "dense"
            if res.info["status"] != "converged":
                info.update(status="partial", reason=f"{res.info['reason']}; rigid-body modes may be missing")
                warnings.warn(f"rigid_body_modes: detection on {model.name} incomplete: {info['reason']}",
                              ConvergenceWarning, stacklevel=2)
        except (MorsuiteError, spla.ArpackError) as exc:  # e.g. K indefinite: sigma < 0 is an eigenvalue
            info.update(method="failed", error=str(exc), status="failed",
                        reason=f"the detection raised ({exc}); treated as having no rigid-body modes")
            warnings.warn(f"rigid_body_modes: detection on {model.name} failed: {info['reason']}",
                          ConvergenceWarning, stacklevel=2)
            lam, Phi, lu = np.zeros(0), np.zeros((n1, 0)), None
        info.update(sigma=sigma, lu_count=int(solver.stats.factorizations))
    if info["method"] != "diagonal-dominance":
        rigid = np.abs(lam) <= rtol * rho
        flex = lam[~rigid]
        low = float(np.sqrt(max(flex.min(), 0.0))) if flex.size else float("nan")
        lam, Phi = lam[rigid], Phi[:, rigid]
        info["max_rigid_eigenvalue"] = float(np.max(np.abs(lam), initial=0.0) / rho)  # relative to rho
        if Phi.shape[1]:
            # one M-orthonormalisation of the (near-degenerate) rigid block: Phi^T M Phi = I to rounding
            Mr = Phi.T @ (model.M @ Phi)
            Phi = Phi @ np.linalg.inv(np.linalg.cholesky(0.5 * (Mr + Mr.T))).T
    Dphi = Phi.T @ (model.D @ Phi)
    absP = np.abs(Phi)
    info["damping_tol"] = float(DAMPING_UNIT * np.sqrt(n1) * np.finfo(float).eps *
                                np.max(absP.T @ (abs(model.D) @ absP), initial=0.0))
    coupling = _coupling(model, Phi, Dphi, lu)
    out = RigidModes(shapes=Phi, eigenvalues=lam, damping=Dphi, coupling=coupling, lowest_flexible=low,
                     info={**info, "time_s": time.perf_counter() - t0})
    model.cache[_CACHE_KEY] = out
    return out


def _coupling(model, Phi, Dphi, lu) -> float:
    r""":math:`\|Z(Z^TAZ)^{-1}Z^TR\|_F / (\delta\,\|Z(Z^TAZ)^{-1}Z^TM\Phi\|_F)`, :math:`R = D\Phi - M\Phi D_\Phi`,
    :math:`A = K - \sigma M`, :math:`\delta = \|D\|_1/\|M\|_1` (the damping's scale): zero iff
    :math:`Z_f^TD\Phi = 0` (:math:`\Phi^TR = 0` by construction); rounding gives about 1e-16."""
    if not Phi.shape[1]:
        return 0.0
    delta = spla.norm(model.D, 1) / spla.norm(model.M, 1)
    if delta == 0:
        return 0.0
    R = model.D @ Phi - model.M @ (Phi @ Dphi)
    MP = model.M @ Phi
    if lu is None:  # dense route: the null-space basis
        Z = sla.null_space(model.G.toarray()) if model.n2 else np.eye(model.n1)
        num, den = np.linalg.norm(Z.T @ R), np.linalg.norm(Z.T @ MP)
    else:
        num, den = np.linalg.norm(lu.solve(R)), np.linalg.norm(lu.solve(MP))
    return float(num / (delta * den)) if den > 0 else 0.0


def flexible_part(model, *, coupling_tol: float = COUPLING_TOL):
    r"""The model restricted to the M-orthogonal complement of its rigid-body modes (module docstring).

    Parameters
    ----------
    model : Index3Model
        A model with rigid-body modes (:func:`rigid_body_modes`, computed if not cached).
    coupling_tol : float
        Largest damping coupling accepted (default :data:`COUPLING_TOL` = 1e-10).

    Returns
    -------
    Index3Model
        Same M, D, K, F, L, band; G with the k rows :math:`\Phi^TM` appended (each scaled to
        unit largest entry); name ``"<name> [flexible]"``; its own cache records that it has
        no rigid-body modes. Cached in ``model.cache["flexible_part"]``. For a model without
        rigid-body modes, ``model`` itself.

    Raises
    ------
    ModelError
        If the damping couples the rigid and flexible modes above ``coupling_tol``: the
        deflation would not be exact (assumption in the module docstring).

    Cost: O(nnz(M) k) to form the rows; no LU.
    """
    from .index3 import Index3Model

    rigid = rigid_body_modes(model)
    if not rigid.k:
        return model
    if rigid.coupling > coupling_tol:
        raise ModelError(
            f"the damping D of model {model.name} couples its {rigid.k} rigid-body modes to the flexible ones "
            f"(relative coupling {rigid.coupling:.2e} > {coupling_tol:.0e}): the rigid part cannot be deflated "
            "exactly. Deflation assumes D Phi in M Phi R^(k x k) + range(G^T), e.g. Rayleigh damping "
            "D = alpha M + beta K, or D Phi = 0")
    cached = model.cache.get("flexible_part")
    if cached is not None:
        return cached
    B = np.asarray((model.M @ rigid.shapes).T)
    B /= np.max(np.abs(B), axis=1, keepdims=True)
    G = sp.vstack([model.G, sp.csr_matrix(B)], format="csr")
    flex = Index3Model(model.M, model.D, model.K, G, model.F, model.L, name=f"{model.name} [flexible]",
                       band=model.band, check_constraints=False)
    if model.lu_backend != "auto":
        flex.lu_backend = model.lu_backend
    flex.cache[_CACHE_KEY] = RigidModes(np.zeros((model.n1, 0)), np.zeros(0), np.zeros((0, 0)),
                                        info={"method": "deflated", "rtol": RTOL})
    flex.deflated_from = {"model": model.name, "rigid_modes": rigid.k}
    model.cache["flexible_part"] = flex
    return flex


def rigid_block(model):
    r"""The rigid part as second-order arrays :math:`(I, D_\Phi, 0, \Phi^TF, L\Phi)` (module docstring)."""
    rigid = rigid_body_modes(model)
    Phi, k = rigid.shapes, rigid.k
    return np.eye(k), rigid.damping.copy(), np.zeros((k, k)), Phi.T @ model.F, model.L @ Phi


def with_rigid(model, rom):
    r"""``rom`` (of the flexible part) with the model's rigid part added back exactly (module docstring).

    A :class:`~morsuite.rom.SecondOrderROM` of order r becomes one of order r + k (rigid
    coordinates first: :math:`\hat M = \mathrm{blkdiag}(I, \hat M_f)`, ...); a
    :class:`~morsuite.rom.FirstOrderROM` of N states one of N + 2k, the rigid block in the
    realization of :meth:`~morsuite.rom.SecondOrderROM.first_order`. The result carries ``flexible`` (the
    given ``rom``) and ``rigid_order`` (k), which :func:`split` reads.

    Cost: O((r + k)^2) dense copies.
    """
    from ..rom import FirstOrderROM, SecondOrderROM

    Mr, Dr, Kr, Fr, Lr = rigid_block(model)
    k = Mr.shape[0]
    if isinstance(rom, SecondOrderROM):
        basis = None if rom.basis is None else np.hstack([rigid_body_modes(model).shapes, rom.basis])
        out = SecondOrderROM(sla.block_diag(Mr, rom.M), sla.block_diag(Dr, rom.D), sla.block_diag(Kr, rom.K),
                             np.vstack([Fr, rom.F]), np.hstack([Lr, rom.L]), basis=basis)
    elif isinstance(rom, FirstOrderROM):
        E, A, B, C = SecondOrderROM(Mr, Dr, Kr, Fr, Lr).first_order()
        phi = rigid_body_modes(model).shapes  # positions of the rigid states [q; q']: Phi q
        basis = None if rom.basis is None else np.hstack([phi, np.zeros_like(phi), rom.basis])
        out = FirstOrderROM(sla.block_diag(E, rom.E), sla.block_diag(A, rom.A), np.vstack([B, rom.B]),
                            np.hstack([C, rom.C]), rom.D, basis=basis)
    else:
        raise InputError(f"rom must be a SecondOrderROM or FirstOrderROM; got {type(rom).__name__}")
    out.flexible = rom
    out.rigid_order = k
    return out


def split(model, rom):
    r"""``(model_part, rom_part, k)`` on which the error norms of ``rom`` are evaluated.

    For a model without rigid-body modes, ``(model, rom, 0)``. For a free-floating model,
    ``(flexible_part(model), rom.flexible, k)`` after checking that ``rom``'s rigid block is
    the model's (the residues :math:`\hat L\hat F` and :math:`\hat L\hat D\hat F` of the
    rigid blocks agree to 1e-10 relative): :math:`T - T_r = T_\text{flex} - T_{r,\text{flex}}`
    exactly.

    Raises
    ------
    InputError
        If the model has rigid-body modes and ``rom`` does not carry them as
        :func:`with_rigid` does, or carries other ones: :math:`T - T_r` has a pole at 0 and
        no finite H2 or H-infinity norm.
    """
    rigid = rigid_body_modes(model)
    if not rigid.k:
        return model, rom, 0
    flex_rom = getattr(rom, "flexible", None)
    k = getattr(rom, "rigid_order", None)
    if flex_rom is None:  # e.g. read back from a file: the block structure of with_rigid, exactly
        flex_rom, k = _recover(rom, rigid.k), rigid.k
    if flex_rom is None or k != rigid.k:
        raise InputError(f"rom: model {model.name} has {rigid.k} rigid-body modes and this reduced model does not "
                         "carry them as a separate block (reducers add them back; morsuite.models.rigid.with_rigid): "
                         "T - T_r has a pole at s = 0 and no finite H2 or H-infinity norm")
    _, Dr, _, Fr, Lr = rigid_block(model)
    if rom.kind == "second-order":
        Dh, Fh, Lh = rom.D[:k, :k], rom.F[:k], rom.L[:, :k]
    else:
        Dh, Fh, Lh = -rom.A[k:2 * k, k:2 * k], rom.B[k:2 * k], rom.C[:, :k]
    scale = np.linalg.norm(Lr) * np.linalg.norm(Fr) * max(1.0, np.linalg.norm(Dr))
    for a, b, what in ((Lh @ Fh, Lr @ Fr, "L F"), (Lh @ Dh @ Fh, Lr @ Dr @ Fr, "L D F")):
        if np.linalg.norm(a - b) > 1e-10 * scale:
            raise InputError(f"rom: its rigid block's {what} differs from the model's rigid part "
                             f"({np.linalg.norm(a - b):.2e}): it is not the rigid part of {model.name}")
    return flexible_part(model), flex_rom, k


def _recover(rom, k):
    """The flexible block of a model written by :func:`with_rigid` and read back (its rigid block
    is exactly decoupled: zero off-diagonal blocks, identity mass, zero stiffness), else None."""
    from ..rom import FirstOrderROM, SecondOrderROM

    def zero(*blocks):
        return all(not np.any(b) for b in blocks)

    if isinstance(rom, SecondOrderROM) and rom.order > k:
        M, D, K = rom.M, rom.D, rom.K
        if (zero(M[:k, k:], M[k:, :k], D[:k, k:], D[k:, :k], K[:k], K[:, :k])
                and np.array_equal(M[:k, :k], np.eye(k))):
            return SecondOrderROM(M[k:, k:], D[k:, k:], K[k:, k:], rom.F[k:], rom.L[:, k:])
    if isinstance(rom, FirstOrderROM) and rom.order > 2 * k:
        j = 2 * k
        E, A = rom.E, rom.A
        if (zero(E[:j, j:], E[j:, :j], A[:j, j:], A[j:, :j], A[:k, :k], A[k:j, :k], rom.B[:k], rom.C[:, k:j])
                and np.array_equal(E[:j, :j], np.eye(j)) and np.array_equal(A[:k, k:j], np.eye(k))):
            return FirstOrderROM(E[j:, j:], A[j:, j:], rom.B[j:], rom.C[:, j:], rom.D)
    return None
