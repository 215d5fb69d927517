r"""Random constrained mass-spring-damper systems for stress tests.

:func:`random_constrained` draws a connected network of ``n1`` masses (a chain
backbone plus random extra springs and springs to the ground), so that

.. math::

    M \ddot x + D \dot x + K x + G^T z = F u, \qquad G x = 0, \qquad y = L x

has symmetric positive definite, sparse :math:`M` (lumped: diagonal; or
consistent: tridiagonal, diagonally dominant) and :math:`K` (a weighted graph
Laplacian plus a positive diagonal), a damping matrix :math:`D` chosen by a
target modal damping ratio :math:`\zeta` (from nearly undamped, :math:`10^{-6}`,
to overdamped, :math:`\zeta > 1`), and a constraint matrix :math:`G` with full
row rank :math:`n_2 \le n_1/2` by construction (every row owns a pivot column
that no other row touches).

Damping (option ``damping``)
----------------------------
``"rayleigh"``
    :math:`D = a M + b K` with :math:`a, b` such that the modal damping ratio
    :math:`\zeta_i = a/(2\omega_i) + b\omega_i/2` equals ``zeta`` at the lowest
    and highest undamped eigenfrequency (proportional damping).
``"dashpots"``
    Dashpots on a random half of the springs, each with
    :math:`c_e = 2\zeta\sqrt{k_e m_e}`, plus Rayleigh damping at
    :math:`10^{-3}\zeta` so that no mode is undamped: non-proportional.
``"none"``
    :math:`D = 0`: every pole on the imaginary axis (a hard case).

Conditioning and units
----------------------
Masses are drawn log-uniformly over :math:`[1, 10^{\text{mass\_spread}}]` and
stiffnesses over :math:`[1, 10^{\text{stiffness\_spread}}]` (0 to 16 decades),
then multiplied by ``mass_unit`` and ``stiffness_unit`` (e.g. 1e-6 and 1e9:
grams and kN/mm). Damping is computed afterwards, so ``zeta`` keeps its meaning.

Default band
------------
The undamped eigenfrequencies :math:`\omega = \sqrt{\lambda(K, M)}` of the
unconstrained system bound those of the constrained one (Cauchy interlacing of
the Rayleigh quotient on :math:`\ker G`). The largest is bounded by the
Gershgorin bound of :math:`M^{-1/2} K M^{-1/2}` (exact for lumped M; Gershgorin
of :math:`D_M^{-1} K` times 2 for consistent M, whose scaled spectrum lies in
[1/2, 3/2]), the smallest is estimated by a few shift-invert Lanczos steps
(one sparse LU of K). The band is a decade beyond that range, widened by
:math:`2\zeta` for overdamped models (their slow poles sit near
:math:`-\omega/(2\zeta)`, their fast ones near :math:`-2\zeta\omega`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError
from .index3 import Index3Model

__all__ = ["random_constrained", "eigenfrequency_range", "default_band"]

DAMPING = ("rayleigh", "dashpots", "none")
MASS = ("lumped", "consistent")
CONSTRAINTS = ("ties", "fixes", "general", "mixed")
IO = ("points", "dense")


def _int(name, value, lo, hi=None):
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputError(f"{name} must be an integer; got {value!r}")
    v = int(value)
    if v < lo or (hi is not None and v > hi):
        rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise InputError(f"{name} must be an integer {rng}; got {v}")
    return v


def _real(name, value, lo=None, hi=None, *, open_lo=False):
    if isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be a number; got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a number; got {value!r}") from exc
    bad = not np.isfinite(v) or (lo is not None and (v < lo or (open_lo and v == lo))) or (hi is not None and v > hi)
    if bad:
        lb = "(" if open_lo else "["
        raise InputError(f"{name} must be finite and in {lb}{lo if lo is not None else '-inf'}, "
                         f"{hi if hi is not None else 'inf'}]; got {value!r}")
    return v


def _choice(name, value, choices):
    if value not in choices:
        raise InputError(f"{name} must be one of {', '.join(map(repr, choices))}; got {value!r}")
    return value


def _loguniform(rng, decades, size):
    return 10.0 ** rng.uniform(0.0, decades, size) if decades > 0 else np.ones(size)


def _laplacian(n, i, j, w):
    """Weighted graph Laplacian of the edges (i, j) with weights w (sparse CSR)."""
    rows = np.concatenate([i, j, i, j])
    cols = np.concatenate([i, j, j, i])
    vals = np.concatenate([w, w, -w, -w])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def eigenfrequency_range(M, K, *, lumped: bool | None = None) -> tuple[float, float]:
    r"""Cheap bounds ``(w_lo, w_hi)`` of the undamped eigenfrequencies :math:`\sqrt{\lambda(K, M)}`.

    ``w_hi`` is a Gershgorin upper bound (no iteration). ``w_lo`` comes from
    shift-invert Lanczos at 0 with a loose tolerance (one sparse LU of K),
    falling back to a dense solve for tiny n and to ``w_hi / 10**8`` if
    Lanczos does not converge. Only meant to place a frequency band.
    """
    M, K = sp.csr_matrix(M), sp.csr_matrix(K)
    n = M.shape[0]
    md = M.diagonal()
    if lumped is None:
        lumped = M.nnz == np.count_nonzero(md)
    absK = abs(K)
    if lumped:
        s = 1.0 / np.sqrt(md)
        gersh = float(np.max(s * (absK @ s)))
    else:
        # D_M^-1/2 M D_M^-1/2 has spectrum >= 1/2 when M is diagonally dominant by 2x
        s = 1.0 / np.sqrt(md)
        gersh = 2.0 * float(np.max(s * (absK @ s)))
    if n <= 40:
        import scipy.linalg as sla
        lam = sla.eigh(K.toarray(), M.toarray(), eigvals_only=True)
        return float(np.sqrt(max(lam[0], 0.0))), float(np.sqrt(lam[-1]))
    try:
        # a fixed start vector: ARPACK's default is random, and the band (hence D) must
        # be a deterministic function of the arguments
        lam0 = spla.eigsh(sp.csc_matrix(K), k=1, M=sp.csc_matrix(M), sigma=0.0, which="LM", tol=1e-3,
                          maxiter=200, v0=np.ones(n), return_eigenvectors=False)[0]
        lo = float(np.sqrt(max(lam0, 0.0)))
    except (spla.ArpackNoConvergence, spla.ArpackError, RuntimeError):
        lo = 0.0
    hi = float(np.sqrt(gersh))
    if not lo > 0:
        lo = hi * 1e-8
    return lo, hi


def default_band(w_lo: float, w_hi: float, zeta: float) -> tuple[float, float]:
    """A decade beyond ``[w_lo, w_hi]``, widened by ``2 zeta`` for overdamped models."""
    widen = max(1.0, 2.0 * zeta)
    return (w_lo / (10.0 * widen), w_hi * 10.0 * widen)


def random_constrained(n1: int = 40, n2: int = 2, m: int = 2, p: int = 2, *, seed: int = 0,
                       zeta: float = 0.05, damping: str = "rayleigh", mass: str = "lumped",
                       mass_spread: float = 0.0, stiffness_spread: float = 0.0,
                       mass_unit: float = 1.0, stiffness_unit: float = 1.0,
                       constraints: str = "mixed", extra_springs: float = 0.3, io: str = "points",
                       name: str | None = None) -> Index3Model:
    r"""A random constrained mass-spring-damper system (see the module docstring).

    Parameters
    ----------
    n1 : int, >= 4
        Number of masses (coordinates).
    n2 : int, 0 <= n2 <= n1 // 2
        Number of constraints; G has full row rank by construction.
    m, p : int, >= 1
        Number of inputs (columns of F) and outputs (rows of L).
    seed : int, >= 0
        Seed of ``numpy.random.default_rng``: the same arguments give the same model.
    zeta : float, >= 0
        Target modal damping ratio: 1e-6 is nearly undamped, > 1 overdamped.
        Ignored for ``damping="none"``.
    damping : {"rayleigh", "dashpots", "none"}
    mass : {"lumped", "consistent"}
        Diagonal M, or tridiagonal M with off-diagonal entries of at most a
        quarter of the smaller neighbouring mass (diagonally dominant).
    mass_spread, stiffness_spread : float in [0, 16]
        Decades over which masses and spring constants are spread (log-uniform).
    mass_unit, stiffness_unit : float > 0
        Scale factors applied to M and K (units).
    constraints : {"ties", "fixes", "general", "mixed"}
        Rows :math:`x_a - x_b = 0` (ties), :math:`x_a = 0` (fixes),
        :math:`g_a x_a + \sum_j g_j x_j = 0` with random weights on one to three
        other coordinates (general), or a random mix. Supports of different
        rows are disjoint, so :math:`G M^{-1} G^T` is well conditioned after
        row equilibration.
    extra_springs : float in [0, 4]
        Random extra springs (beyond the chain) per mass.
    io : {"points", "dense"}
        Point forces and point sensors at random masses (one to three per
        column/row, random signs), or dense Gaussian F and L.
    name : str, optional

    Returns
    -------
    Index3Model
        With ``band`` from :func:`default_band` and the draw recorded in
        ``model.generator`` (plain data: parameters and the eigenfrequency range).

    Raises
    ------
    InputError
        For any parameter out of range (the message names it).
    """
    n1 = _int("n1", n1, 4)
    n2 = _int("n2", n2, 0, n1 // 2)
    m = _int("m", m, 1)
    p = _int("p", p, 1)
    seed = _int("seed", seed, 0)
    zeta = _real("zeta", zeta, 0.0, 1e6)
    damping = _choice("damping", damping, DAMPING)
    mass = _choice("mass", mass, MASS)
    mass_spread = _real("mass_spread", mass_spread, 0.0, 16.0)
    stiffness_spread = _real("stiffness_spread", stiffness_spread, 0.0, 16.0)
    mass_unit = _real("mass_unit", mass_unit, 0.0, None, open_lo=True)
    stiffness_unit = _real("stiffness_unit", stiffness_unit, 0.0, None, open_lo=True)
    constraints = _choice("constraints", constraints, CONSTRAINTS)
    extra_springs = _real("extra_springs", extra_springs, 0.0, 4.0)
    io = _choice("io", io, IO)
    if damping == "none":
        zeta = 0.0
    rng = np.random.default_rng(seed)
    perm = rng.permutation(n1)  # the chain visits the masses in random order

    # -- masses
    masses = _loguniform(rng, mass_spread, n1)
    if mass == "lumped":
        M = sp.diags(masses, format="csr")
    else:
        i, j = perm[:-1], perm[1:]
        c = 0.25 * rng.uniform(0.2, 1.0, n1 - 1) * np.minimum(masses[i], masses[j])
        M = sp.diags(masses, format="csr") + sp.csr_matrix((np.concatenate([c, c]),
                                                             (np.concatenate([i, j]), np.concatenate([j, i]))),
                                                            shape=(n1, n1))

    # -- springs: chain backbone + random extras + ground springs
    ei, ej = list(perm[:-1]), list(perm[1:])
    n_extra = int(round(extra_springs * n1))
    if n_extra:
        a = rng.integers(0, n1, n_extra)
        b = rng.integers(0, n1, n_extra)
        keep = a != b
        ei += list(a[keep])
        ej += list(b[keep])
    ei, ej = np.asarray(ei, dtype=np.int64), np.asarray(ej, dtype=np.int64)
    ke = _loguniform(rng, stiffness_spread, ei.size)
    # every mass on a ground spring keeps K definite whatever the spread; a few
    # stiff ones (as in DSMS and TCOM) make the lowest mode nontrivial
    kg = _loguniform(rng, stiffness_spread, n1) * rng.uniform(0.05, 0.2, n1)
    K = _laplacian(n1, ei, ej, ke) + sp.diags(kg, format="csr")
    M = (M * mass_unit).tocsr()
    K = (K * stiffness_unit).tocsr()
    ke, kg = ke * stiffness_unit, kg * stiffness_unit
    masses = masses * mass_unit

    w_lo, w_hi = eigenfrequency_range(M, K, lumped=(mass == "lumped"))
    # -- damping
    D = sp.csr_matrix((n1, n1))
    if damping != "none":
        zr = zeta if damping == "rayleigh" else 1e-3 * zeta
        if w_hi > w_lo * (1 + 1e-12):
            # zeta_i = a / (2 w_i) + b w_i / 2 = zr at w_lo and w_hi
            a = 2.0 * zr * w_lo * w_hi / (w_lo + w_hi)
            b = 2.0 * zr / (w_lo + w_hi)
        else:
            a, b = zr * w_lo, zr / max(w_hi, np.finfo(float).tiny)
        D = (a * M + b * K).tocsr()
        if damping == "dashpots":
            sel = rng.random(ei.size) < 0.5
            me = 0.5 * (masses[ei[sel]] + masses[ej[sel]])
            ce = 2.0 * zeta * np.sqrt(ke[sel] * me)
            D = (D + _laplacian(n1, ei[sel], ej[sel], ce)).tocsr()

    # -- constraints: disjoint supports, a pivot column per row
    G = _draw_constraints(rng, n1, n2, constraints)

    # -- inputs and outputs
    if io == "dense":
        F = rng.standard_normal((n1, m))
        L = rng.standard_normal((p, n1))
    else:
        F = np.zeros((n1, m))
        L = np.zeros((p, n1))
        for k in range(m):
            idx = rng.choice(n1, size=int(rng.integers(1, 4)), replace=False)
            F[idx, k] = rng.choice([-1.0, 1.0], idx.size)
        for k in range(p):
            idx = rng.choice(n1, size=int(rng.integers(1, 4)), replace=False)
            L[k, idx] = rng.choice([-1.0, 1.0], idx.size)

    band = default_band(w_lo, w_hi, zeta)
    label = name or f"random(n1={n1},n2={n2},m={m},p={p},seed={seed})"
    fom = Index3Model(M, D, K, G, F, L, name=label, band=band)
    fom.generator = {"family": "random_constrained", "n1": n1, "n2": n2, "m": m, "p": p, "seed": seed,
                     "zeta": zeta, "damping": damping, "mass": mass, "mass_spread": mass_spread,
                     "stiffness_spread": stiffness_spread, "mass_unit": mass_unit,
                     "stiffness_unit": stiffness_unit, "constraints": constraints,
                     "extra_springs": extra_springs, "io": io, "eigenfrequency_range": [w_lo, w_hi],
                     "band": list(band)}
    return fom


def _draw_constraints(rng, n1, n2, kind):
    """n2 rows with pairwise disjoint supports (full row rank by construction)."""
    if n2 == 0:
        return sp.csr_matrix((0, n1))
    cols = rng.permutation(n1)
    free = list(cols[n2:])  # pivots are cols[:n2]; the others are handed out without reuse
    rows, cc, vals = [], [], []
    for r in range(n2):
        k = kind if kind != "mixed" else ("ties", "fixes", "general")[int(rng.integers(0, 3))]
        piv = cols[r]
        if k == "fixes" or not free:
            rows.append(r)
            cc.append(piv)
            vals.append(1.0)
            continue
        if k == "ties":
            rows += [r, r]
            cc += [piv, free.pop()]
            vals += [1.0, -1.0]
            continue
        # general: up to three partners while leaving one for each later row
        spare = len(free) - (n2 - r - 1)
        nk = int(min(rng.integers(1, 4), max(spare, 1)))
        part = [free.pop() for _ in range(min(nk, len(free)))]
        w = rng.uniform(0.5, 2.0, len(part) + 1) * rng.choice([-1.0, 1.0], len(part) + 1)
        rows += [r] * (len(part) + 1)
        cc += [piv] + part
        vals += list(w)
    return sp.csr_matrix((vals, (rows, cc)), shape=(n2, n1))
