"""Generators of the test models (definitions in shared/docs/models.md).

All matrices are in the physical sign convention (M, K positive definite).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import InputError
from .index3 import Index3Model

__all__ = ["dsms", "tcom"]


def _positive(name, value, *, integer=False, minimum=None):
    if integer:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise InputError(f"{name} must be an integer; got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a number; got {value!r}") from exc
    if not np.isfinite(v) or v <= 0 or (minimum is not None and v < minimum):
        lo = f">= {minimum}" if minimum is not None else "> 0"
        raise InputError(f"{name} must be finite and {lo}; got {value!r}")
    return int(value) if integer else v


def _nonneg(name, value):
    v = float(value)
    if not np.isfinite(v) or v < 0:
        raise InputError(f"{name} must be finite and >= 0; got {value!r}")
    return v


def _chain_tridiag(n, diag, off):
    """Symmetric tridiagonal with the given diagonal vector and off-diagonal value."""
    o = np.full(n - 1, float(off))
    return sp.diags([o, np.asarray(diag, dtype=float), o], [-1, 0, 1], format="csr")


def dsms(g: int = 6000, *, mass: float = 100.0, k: float = 2.0, kappa: float = 2.0,
         kappa_end: float = 4.0, d: float = 5.0, delta: float = 5.0, delta_end: float = 10.0,
         free: bool = False, name: str | None = None) -> Index3Model:
    r"""Constrained damped mass-spring system of Mehrmann and Stykel (2005).

    ``g`` equal masses in a chain, springs ``k`` and dampers ``d`` between
    neighbours, springs ``kappa`` and dampers ``delta`` to the ground
    (``kappa_end``, ``delta_end`` at masses 1 and g), and a rigid bar tying
    mass 1 to mass g: :math:`G = e_1^T - e_g^T`. Input: force on mass 1;
    outputs: positions of masses 1, 2 and g - 1 (outputs 2 and 3 coincide by
    symmetry, so :math:`T(s)` has rank 1).

    With the defaults this reproduces the M.E.S.S. ``msd_ind3`` matrices
    (after the sign change of D and K described in models.md): n1 = g, n2 = 1.

    ``free=True`` makes it a free-free chain (``dsms:g=200,free=true``): no springs
    and no dampers to the ground (``kappa``, ``kappa_end``, ``delta``, ``delta_end`` are
    set to 0), so K and D annihilate the common translation :math:`\mathbf 1`, which
    satisfies the tie: one undamped rigid-body mode, a double pole of :math:`T` at
    :math:`s = 0` (:mod:`morsuite.models.rigid`). Without ``free``, grounding springs of
    0 give the same K; a ``delta`` other than ``delta_end`` then damps the rigid mode
    unevenly (coupled to the flexible modes: refused by the deflation).
    """
    g = _positive("g", g, integer=True, minimum=4)
    mass = _positive("mass", mass)
    k, d = _nonneg("k", k), _nonneg("d", d)
    kappa, kappa_end = _nonneg("kappa", kappa), _nonneg("kappa_end", kappa_end)
    delta, delta_end = _nonneg("delta", delta), _nonneg("delta_end", delta_end)
    if not isinstance(free, (bool, np.bool_)):
        raise InputError(f"free must be a bool; got {free!r}")
    if free:
        kappa = kappa_end = delta = delta_end = 0.0
    M = sp.identity(g, format="csr") * mass
    kd = np.full(g, 2 * k + kappa)
    kd[[0, -1]] = k + kappa_end
    dd = np.full(g, 2 * d + delta)
    dd[[0, -1]] = d + delta_end
    K = _chain_tridiag(g, kd, -k)
    D = _chain_tridiag(g, dd, -d)
    G = sp.csr_matrix(([1.0, -1.0], ([0, 0], [0, g - 1])), shape=(1, g))
    F = np.zeros((g, 1))
    F[0, 0] = 1.0
    L = np.zeros((3, g))
    L[0, 0] = L[1, 1] = L[2, g - 2] = 1.0
    label = name or f"dsms(g={g}{', free' if free else ''})"
    return Index3Model(M, D, K, G, F, L, name=label, band=(1e-2, 1.0))


def tcom(nc: int = 2000, *, masses=(1.0, 2.0, 3.0), central_mass: float = 10.0,
         stiffness=(10.0, 20.0, 1.0), k0: float = 50.0, alpha: float = 0.01, beta: float = 0.01,
         v: float = 5.0, constrained: bool = True, constraints: str = "pairs", io: str = "sum",
         name: str | None = None) -> Index3Model:
    r"""Constrained triple chain oscillator (Truhar and Veselic 2009).

    Three chains of ``nc`` masses coupled to one central mass (last index):
    n1 = 3 nc + 1. Chain i has stiffness block :math:`k_i\,\mathrm{tridiag}(-1, 2, -1)`
    and its last mass couples to the central mass with :math:`-k_i`; the central
    diagonal is :math:`k_1 + k_2 + k_3 + k_0`. Damping
    :math:`D = \alpha M + \beta K` plus ``v`` on the diagonal at masses 1, nc
    and 2 nc + 1. Six constraints (``constrained=True``, nc even): within each
    chain, :math:`x_{o+1} = x_{o+nc/2}` and :math:`x_{o+nc/2+1} = x_{o+nc}`.
    Input: the same force on every mass; output: the sum of all positions.

    Variants of the same family (for MIMO and constraint studies; not in the
    literature's TCOM, defined here):

    ``constraints``
        ``"pairs"`` (default): the six ties above. ``"curvature"``: one row per
        chain, zero discrete curvature at its middle,
        :math:`x_{o+h-1} - 2x_{o+h} + x_{o+h+1} = 0` with :math:`h = \lceil nc/2 \rceil`.
        ``"averaging"``: one row per chain, the middle mass at the chain's mean
        position, :math:`x_{o+h} - \frac{1}{nc}\sum_{i=1}^{nc} x_{o+i} = 0`.
        ``constrained=False`` drops every constraint (n2 = 0).
    ``io``
        ``"sum"`` (default): one input, the same force on every mass, and one
        output, the sum of all positions. ``"chains"``: three inputs and three
        outputs, input i the same force on every mass of chain i, output i the
        sum of the positions of chain i. ``"points"``: three inputs and three
        outputs, non-collocated: input i a force on the mass a quarter into chain
        i (0-based index :math:`o + \lfloor nc/4 \rfloor`), output i the position
        of the mass three quarters into it (:math:`o + \lfloor 3nc/4 \rfloor`).
    """
    nc = _positive("nc", nc, integer=True, minimum=2)
    if constraints not in ("pairs", "curvature", "averaging"):
        raise InputError(f"constraints must be 'pairs', 'curvature' or 'averaging'; got {constraints!r}")
    if io not in ("sum", "chains", "points"):
        raise InputError(f"io must be 'sum', 'chains' or 'points'; got {io!r}")
    if constrained and constraints == "pairs" and nc % 2:
        raise InputError(f"nc must be even for the constrained TCOM; got {nc}")
    if constrained and constraints != "pairs" and nc < 3:
        raise InputError(f"nc must be >= 3 for constraints={constraints!r}; got {nc}")
    if len(masses) != 3 or len(stiffness) != 3:
        raise InputError("masses and stiffness must have three entries (one per chain)")
    ms_ = [_positive(f"masses[{i}]", x) for i, x in enumerate(masses)]
    ks = [_positive(f"stiffness[{i}]", x) for i, x in enumerate(stiffness)]
    central_mass = _positive("central_mass", central_mass)
    k0 = _nonneg("k0", k0)
    alpha, beta, v = _nonneg("alpha", alpha), _nonneg("beta", beta), _nonneg("v", v)
    n1 = 3 * nc + 1
    c = n1 - 1
    mdiag = np.concatenate([np.full(nc, ms_[i]) for i in range(3)] + [[central_mass]])
    M = sp.diags(mdiag, format="csr")
    blocks = [ks[i] * _chain_tridiag(nc, np.full(nc, 2.0), -1.0) for i in range(3)]
    Kc = sp.block_diag(blocks + [sp.csr_matrix([[sum(ks) + k0]])], format="lil")
    for i in range(3):
        last = i * nc + nc - 1
        Kc[last, c] = -ks[i]
        Kc[c, last] = -ks[i]
    K = sp.csr_matrix(Kc)
    D = (alpha * M + beta * K).tolil()
    for idx in (0, nc - 1, 2 * nc):
        D[idx, idx] += v
    D = sp.csr_matrix(D)
    G = _tcom_constraints(nc, n1, constraints) if constrained else sp.csr_matrix((0, n1))
    if io == "sum":
        F = np.ones((n1, 1))
        L = np.ones((1, n1))
    elif io == "chains":
        F = np.zeros((n1, 3))
        for ch in range(3):
            F[ch * nc:(ch + 1) * nc, ch] = 1.0
        L = F.T.copy()
    else:
        F, L = np.zeros((n1, 3)), np.zeros((3, n1))
        for ch in range(3):
            F[ch * nc + nc // 4, ch] = 1.0
            L[ch, ch * nc + (3 * nc) // 4] = 1.0
    extra = "" if constraints == "pairs" or not constrained else f", constraints={constraints}"
    extra += "" if io == "sum" else f", io={io}"
    return Index3Model(M, D, K, G, F, L, name=name or f"tcom(nc={nc}{extra})", band=(1e-3, 1.0))


def _tcom_constraints(nc: int, n1: int, kind: str):
    """Constraint rows of the TCOM variants (0-based indices; see :func:`tcom`)."""
    rows, cols, vals = [], [], []
    r = 0
    for ch in range(3):
        o = ch * nc
        if kind == "pairs":
            h = nc // 2
            for a, b in ((o, o + h - 1), (o + h, o + nc - 1)):
                rows += [r, r]
                cols += [a, b]
                vals += [1.0, -1.0]
                r += 1
            continue
        mid = o + (nc + 1) // 2 - 1  # the middle mass, x_{o+h} with h = ceil(nc/2)
        if kind == "curvature":
            cols += [mid - 1, mid, mid + 1]
            vals += [1.0, -2.0, 1.0]
            rows += [r] * 3
        else:  # averaging
            w = np.full(nc, -1.0 / nc)
            w[mid - o] += 1.0
            cols += list(range(o, o + nc))
            vals += w.tolist()
            rows += [r] * nc
        r += 1
    return sp.csr_matrix((vals, (rows, cols)), shape=(r, n1))
