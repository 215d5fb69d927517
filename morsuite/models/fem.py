r"""Finite-element models of constrained elastic structures (scikit-fem).

A box :math:`[0, L_x] \times [0, L_y] \times [0, L_z]` of linear-elastic material
(3D trilinear hexahedra, or 2D bilinear quadrilaterals in plane stress of
thickness ``thickness``), meshed by a uniform tensor grid, clamped on its face
:math:`x = 0` (or free: ``clamp="none"``, a free-free body with its rigid-body modes,
:mod:`morsuite.models.rigid`), optionally cut at mid-length into two separately meshed bodies
joined by tie constraints. All constraints are Lagrange multipliers in
:math:`G`:

- clamped face: one row :math:`e_i^T` per DOF of every node with :math:`x = 0`;
- tie: one row :math:`e_a^T - e_b^T` per component of every pair of coincident
  interface nodes (:math:`a` in the first body, :math:`b` in the second).

.. math::

    M \ddot x + D \dot x + K x + G^T z = F u,\quad G x = 0,\quad y = L x,
    \qquad D = \alpha M + \beta K \ \text{(Rayleigh)}.

Inputs are unit forces and outputs displacements at named points of the box
(the nearest mesh node, first in node order on a tie) in a direction ``x``,
``y`` or ``z``, written ``"point:direction"``:

============  ======================================================
``tip``       centre of the free face, :math:`(L_x, L_y/2, L_z/2)`
``mid``       centre of the box, :math:`(L_x/2, L_y/2, L_z/2)`
``quarter``   :math:`(L_x/4, L_y/2, L_z/2)`
``corner``    free corner, :math:`(L_x, L_y, L_z)`
``edge``      middle of a free edge, :math:`(L_x, L_y, L_z/2)`
============  ======================================================

In 2D the box is :math:`[0, L_x] \times [0, L_y]` (``length`` x ``height``,
``nx`` x ``ny`` elements; ``width`` and ``nz`` are unused) and directions are
``x`` and ``y``. Validation (beam theory, a dense null-space computation, tied
against monolithic meshes) and assembly timings: ``docs/design/fem.md``.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import InputError
from .fem_assembly import clamp_rows, constraint_matrix, grid_body, lame_plane, tie_rows
from .generators import _nonneg, _positive
from .index3 import Index3Model

__all__ = ["fem_beam", "fem_block", "eigenfrequencies", "eb_cantilever_omega", "POINTS"]

#: named points as fractions of the box sizes (x, y, z)
POINTS = {"tip": (1.0, 0.5, 0.5), "mid": (0.5, 0.5, 0.5), "quarter": (0.25, 0.5, 0.5),
          "corner": (1.0, 1.0, 1.0), "edge": (1.0, 1.0, 0.5)}
_DIRS = {"x": 0, "y": 1, "z": 2}
#: boundary conditions: clamped on the face x = 0, or none (free-free: 6 rigid-body modes in 3D, 3 in 2D)
CLAMPS = ("x0", "none")
#: Euler-Bernoulli cantilever eigenvalue parameters beta_k L (first two bending modes)
EB_ROOTS = (1.8751040687119611, 4.6940911329741745)


def _int(name, value, minimum=1):
    return _positive(name, value, integer=True, minimum=minimum)


def _points(name, spec, dim):
    """Parse ``"tip:z"`` / ``"tip:z;mid:y"`` / a sequence into (point, direction) pairs."""
    items = spec.split(";") if isinstance(spec, str) else list(spec) if spec is not None else []
    if not items:
        raise InputError(f"{name} must name at least one point (e.g. 'tip:z'); got {spec!r}")
    out = []
    for item in items:
        if not isinstance(item, str):
            raise InputError(f"{name}: expected 'point:direction' strings; got {item!r}")
        pt, _, d = item.strip().partition(":")
        if pt not in POINTS:
            raise InputError(f"{name}: unknown point {pt!r} in {item!r}; known: {', '.join(POINTS)}")
        if d not in _DIRS or _DIRS[d] >= dim:
            valid = ", ".join(list(_DIRS)[:dim])
            raise InputError(f"{name}: direction of {item!r} must be one of {valid} ({dim}D)")
        out.append((pt, _DIRS[d]))
    return out


def _assemble(dim, n, size, E, nu, rho, thickness, bodies):
    lam, mu = lame_plane(E, nu, dim)
    axes = [np.linspace(0.0, size[k], n[k] + 1) for k in range(dim)]
    if bodies == 1:
        parts = [grid_body(axes, lam, mu, rho, thickness)]
        cut = None
    else:
        na = n[0] // 2
        cut = axes[0][na]
        parts = [grid_body([axes[0][:na + 1]] + axes[1:], lam, mu, rho, thickness),
                 grid_body([axes[0][na:]] + axes[1:], lam, mu, rho, thickness)]
    return parts, cut


def _clamp(clamp):
    if clamp not in CLAMPS:
        raise InputError(f"clamp must be one of {', '.join(map(repr, CLAMPS))}; got {clamp!r}")
    return clamp


def _structure(*, dim, n, size, E, nu, rho, thickness, alpha, beta, bodies, inputs, outputs,
               name, band, clamp="x0"):
    import scipy.sparse as sp
    t0 = time.perf_counter()
    parts, cut = _assemble(dim, n, size, E, nu, rho, thickness, bodies)
    t_bodies = time.perf_counter() - t0
    offs = np.cumsum([0] + [b.ndof for b in parts])
    n1 = int(offs[-1])
    K = sp.block_diag([b.K for b in parts], format="csr")
    M = sp.block_diag([b.M for b in parts], format="csr")
    tol = 1e-9 * max(size[:dim])
    clamped = clamp_rows(parts[0], 0, 0, 0.0, tol) if clamp == "x0" else np.zeros(0, dtype=np.int64)
    ta = tb = np.zeros(0, dtype=np.int64)
    if cut is not None:
        ta, tb = tie_rows(parts[0], offs[0], parts[1], offs[1], 0, cut, tol)
    G = constraint_matrix(clamped, ta, tb, n1)
    D = (alpha * M + beta * K).tocsr() if beta else (alpha * M).tocsr()
    coords = np.hstack([b.p for b in parts])
    dofmap = np.hstack([b.nodal_dofs + o for b, o in zip(parts, offs)])
    F = _selection(inputs, coords, dofmap, size, dim, n1).T
    L = _selection(outputs, coords, dofmap, size, dim, n1)
    # full row rank holds by construction (constraint_matrix checks it structurally),
    # so the dense G M^-1 G^T test of Index3Model (one LU of M, n1 x n2 dense) is skipped
    model = Index3Model(M, D, K, G, F, L, name=name, band=band, check_constraints=False)
    model.fem = {"dim": dim, "elements": list(n), "size": list(size[:dim]), "bodies": bodies,
                 "E": E, "nu": nu, "rho": rho, "thickness": thickness, "alpha": alpha, "beta": beta,
                 "clamp": clamp, "n_clamped": int(clamped.size), "n_tied": int(ta.size),
                 "inputs": [f"{p}:{'xyz'[c]}" for p, c in inputs],
                 "outputs": [f"{p}:{'xyz'[c]}" for p, c in outputs],
                 "assembly_s": round(time.perf_counter() - t0, 4), "bodies_s": round(t_bodies, 4)}
    return model


def _selection(points, coords, dofmap, size, dim, n1):
    """(len(points), n1) rows selecting the DOF of the node nearest each named point."""
    S = np.zeros((len(points), n1))
    for i, (pt, c) in enumerate(points):
        target = np.array([POINTS[pt][k] * size[k] for k in range(dim)])
        node = int(np.argmin(np.sum((coords - target[:, None]) ** 2, axis=0)))
        S[i, dofmap[c, node]] = 1.0
    return S


def _common(nu, E, rho, thickness, alpha, beta, bodies, nx, dim):
    E, rho, thickness = _positive("E", E), _positive("rho", rho), _positive("thickness", thickness)
    try:
        nu = float(nu)
    except (TypeError, ValueError) as exc:
        raise InputError(f"nu must be a number; got {nu!r}") from exc
    if not -1.0 < nu < 0.5:
        raise InputError(f"nu must be in (-1, 0.5); got {nu!r}")
    alpha, beta = _nonneg("alpha", alpha), _nonneg("beta", beta)
    if bodies not in (1, 2) or isinstance(bodies, bool):
        raise InputError(f"bodies must be 1 or 2; got {bodies!r}")
    if bodies == 2 and nx < 2:
        raise InputError(f"nx must be >= 2 for bodies=2 (one element per body at least); got {nx}")
    if dim not in (2, 3) or isinstance(dim, bool):
        raise InputError(f"dim must be 2 or 3; got {dim!r}")
    return nu, E, rho, thickness, alpha, beta


def eb_cantilever_omega(k, *, length, width, height, E, rho, direction="z", dim=3):
    r"""Euler-Bernoulli angular eigenfrequency of bending mode ``k`` (1 or 2) of a cantilever.

    :math:`\omega_k = (\beta_k L)^2 \sqrt{EI / (\rho A L^4)}` with
    :math:`\beta_1 L = 1.8751`, :math:`\beta_2 L = 4.6941`; bending in ``z``
    (3D: :math:`I = w h^3/12`) or ``y`` (3D: :math:`I = h w^3/12`; 2D: the
    in-plane height). The reference of ``tests/test_fem.py``.
    """
    if dim == 2 or direction == "z":
        r_ = height
    else:
        r_ = width
    return EB_ROOTS[k - 1] ** 2 * np.sqrt(E * r_ ** 2 / 12.0 / (rho * length ** 4))


def fem_beam(nx: int = 40, ny: int = 4, nz: int = 4, *, dim: int = 3, length: float = 1.0,
             width: float = 0.1, height: float = 0.1, E: float = 1.0, nu: float = 0.3,
             rho: float = 1.0, thickness: float = 1.0, alpha: float = 1e-3, beta: float = 1e-2,
             bodies: int = 1, inputs=None, outputs=None, clamp: str = "x0",
             name: str | None = None) -> Index3Model:
    r"""Clamped elastic beam (cantilever): a finite-element :class:`Index3Model`.

    A box ``length`` x ``width`` x ``height`` (2D: ``length`` x ``height``)
    meshed by ``nx`` x ``ny`` x ``nz`` trilinear hexahedra (2D: ``nx`` x ``ny``
    plane-stress quadrilaterals), clamped at :math:`x = 0` (module docstring).
    n1 = 3 (nx+1)(ny+1)(nz+1) in 3D (2 (nx+1)(ny+1) in 2D), plus the duplicated
    interface nodes when ``bodies=2``; n2 = the clamped DOFs plus the tied ones.

    Parameters
    ----------
    nx, ny, nz : int
        Elements along x, y, z (>= 1). Default 40 x 4 x 4: n1 = 3,075.
    dim : int
        3 (hexahedra, default) or 2 (quadrilaterals, plane stress).
    length, width, height : float
        Box sizes (default 1 x 0.1 x 0.1: slenderness 10).
    E, nu, rho, thickness : float
        Young's modulus (default 1), Poisson ratio in (-1, 0.5) (0.3), density (1),
        2D thickness (1). Units are the caller's; the defaults are nondimensional.
    alpha, beta : float
        Rayleigh damping :math:`D = \alpha M + \beta K` (defaults 1e-3, 1e-2: about
        0.5% of critical damping at the first bending mode of the default beam).
    bodies : int
        1 (default) or 2: two bodies meshed separately, cut at element ``nx // 2``,
        joined by tie constraints :math:`u_a - u_b = 0` (same displacement space as
        one body: the eigenfrequencies agree with ``bodies=1``).
    inputs, outputs : str or sequence of str
        ``"point:direction"`` items, ``;``-separated in one string; default
        ``"tip:z"`` and ``"tip:z;mid:z"`` (2D: ``y``).
    clamp : {"x0", "none"}
        ``"x0"`` (default): clamped on the face :math:`x = 0`. ``"none"``: free-free, no
        clamp rows (only the ties of ``bodies=2``): K is singular on :math:`\ker G` with
        the rigid-body modes (6 in 3D, 3 in 2D; :mod:`morsuite.models.rigid`); the band
        stays the cantilever's.
    name : str, optional
        Label (default ``fem_beam(...)`` with the sizes).

    Returns
    -------
    Index3Model
        With ``band`` = (0.1, 30) times the Euler-Bernoulli first bending
        frequency (:func:`eb_cantilever_omega`, weaker direction), and a plain-data
        ``model.fem`` dict (mesh, material, constraint counts, assembly time).

    Cost: assembly O(nnz) plus one sparse COO-to-CSR sort (timings at n1 = 1e3 to 2e5 in
    ``docs/design/fem.md``). Deterministic: the same arguments give the same bits.
    """
    dim = int(dim) if isinstance(dim, (int, np.integer)) and not isinstance(dim, bool) else dim
    nx, ny = _int("nx", nx), _int("ny", ny)
    nz = _int("nz", nz) if dim == 3 else 1
    nu, E, rho, thickness, alpha, beta = _common(nu, E, rho, thickness, alpha, beta, bodies, nx, dim)
    clamp = _clamp(clamp)
    length, width, height = (_positive("length", length), _positive("width", width),
                             _positive("height", height))
    d = "z" if dim == 3 else "y"
    ins = _points("inputs", inputs if inputs is not None else f"tip:{d}", dim)
    outs = _points("outputs", outputs if outputs is not None else f"tip:{d};mid:{d}", dim)
    size = (length, width, height) if dim == 3 else (length, height)
    n = (nx, ny, nz) if dim == 3 else (nx, ny)
    w1 = min(eb_cantilever_omega(1, length=length, width=width, height=height, E=E, rho=rho,
                                 direction=c, dim=dim) for c in "yz")
    label = name or (f"fem_beam(nx={nx}, ny={ny}" + (f", nz={nz}" if dim == 3 else ", dim=2")
                     + (", bodies=2" if bodies == 2 else "") + (", clamp=none" if clamp == "none" else "") + ")")
    return _structure(dim=dim, n=n, size=size, E=E, nu=nu, rho=rho, thickness=thickness,
                      alpha=alpha, beta=beta, bodies=bodies, inputs=ins, outputs=outs,
                      name=label, band=(0.1 * w1, 30.0 * w1), clamp=clamp)


def fem_block(n1: int = 20000, *, aspect=(1.0, 1.0, 1.0), E: float = 1.0, nu: float = 0.3,
              rho: float = 1.0, alpha: float = 1e-3, beta: float = 1e-2, bodies: int = 1,
              inputs="corner:z", outputs="corner:z;mid:z", clamp: str = "x0",
              name: str | None = None) -> Index3Model:
    r"""3D elastic block clamped on one face (or free), sized by its number of positions.

    A box of sides ``aspect`` (default the unit cube) meshed by trilinear
    hexahedra of nearly cubic shape, clamped at :math:`x = 0`, with
    :math:`3 (n_x+1)(n_y+1)(n_z+1) \approx` ``n1`` (the mesh closest to the
    requested n1 with elements of equal size along the axes; ``model.n1`` is the
    exact count). A benchmark of sparse saddle-point solvers: 3D stencils of 81
    nonzeros per row, a wide band, a clamped face of
    3 (n_y+1)(n_z+1) constraint rows.

    Parameters
    ----------
    n1 : int
        Target number of positions (>= 81, a 2 x 2 x 2-node mesh; 1e3 to 1e5 and
        beyond are typical).
    aspect : (float, float, float)
        Box sizes along x, y, z.
    E, nu, rho, alpha, beta, bodies, inputs, outputs, clamp, name
        As in :func:`fem_beam` (default input ``corner:z``, outputs ``corner:z``
        and ``mid:z``; ``clamp="none"``: a free-free block with six rigid-body modes,
        ``fem_block:n1=500,clamp=none``).

    Returns
    -------
    Index3Model
        ``band`` = (0.01, 10) times :math:`\sqrt{E/\rho}/L_x`; ``model.fem`` as in
        :func:`fem_beam`.

    Cost: as :func:`fem_beam`.
    """
    target = _int("n1", n1, minimum=81)
    try:
        sizes = tuple(float(a) for a in aspect)
    except (TypeError, ValueError) as exc:
        raise InputError(f"aspect must be three positive numbers; got {aspect!r}") from exc
    if len(sizes) != 3:
        raise InputError(f"aspect must be three positive numbers; got {aspect!r}")
    sizes = tuple(_positive(f"aspect[{i}]", a) for i, a in enumerate(sizes))
    # nodes per axis proportional to the side, h = max(side) / k: the count closest to n1
    best = None
    for k in range(1, 10 ** 6):
        n = tuple(max(1, round(s * k / max(sizes))) for s in sizes)
        count = 3 * int(np.prod([ni + 1 for ni in n]))
        if best is None or abs(count - target) < abs(best[0] - target):
            best = (count, n)
        if count > 2 * target:
            break
    n = best[1]
    nu, E, rho, _t, alpha, beta = _common(nu, E, rho, 1.0, alpha, beta, bodies, n[0], 3)
    clamp = _clamp(clamp)
    ins, outs = _points("inputs", inputs, 3), _points("outputs", outputs, 3)
    c = np.sqrt(E / rho) / sizes[0]
    label = name or f"fem_block(n1={target}{', clamp=none' if clamp == 'none' else ''})"
    return _structure(dim=3, n=n, size=sizes, E=E, nu=nu, rho=rho, thickness=1.0, alpha=alpha,
                      beta=beta, bodies=bodies, inputs=ins, outputs=outs, name=label,
                      band=(0.01 * c, 10.0 * c), clamp=clamp)


def eigenfrequencies(model: Index3Model, k: int = 6, *, sigma: float = 0.0):
    r"""The ``k`` lowest undamped angular eigenfrequencies of a constrained model.

    Solves :math:`K x + G^T z = \omega^2 M x`, :math:`G x = 0` by shift-invert Lanczos on the
    saddle-point matrix (:func:`morsuite.linalg.eigen.constrained_modes`, which also returns
    the mode shapes): no null-space basis is formed. Cost: one sparse LU of order n1 + n2
    plus about 3k-5k solves. Returns the sorted :math:`\omega_j` (rad/s).
    """
    from ..linalg.eigen import constrained_modes

    k = _int("k", k)
    if k >= model.order - 1:
        raise InputError(f"k must be < n1 - n2 - 1 = {model.order - 1}; got {k}")
    return np.sort(np.abs(constrained_modes(model, k=k, sigma=sigma).omega))
