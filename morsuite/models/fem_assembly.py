r"""Assembly of linear-elastic finite-element bodies on uniform tensor grids.

The element matrices come from scikit-fem (:mod:`skfem`): trilinear hexahedra
(``ElementVector(ElementHex1)``) in 3D, bilinear quadrilaterals
(``ElementVector(ElementQuad1)``) in plane stress in 2D, Gauss order 2
(exact for both matrices on affine boxes). Stiffness and consistent mass of one
element,

.. math::

    K_e = \int_{\Omega_e} \lambda\,(\nabla\!\cdot u)(\nabla\!\cdot v)
          + 2\mu\,\varepsilon(u):\varepsilon(v)\,dx, \qquad
    M_e = \int_{\Omega_e} \rho\, u\cdot v\,dx,

are assembled by scikit-fem on a one-element mesh. On a uniform grid every
element is a translate of that one (checked, node by node), so the global
matrices are the scatter :math:`K = \sum_e P_e^T K_e P_e` done once with
``scipy.sparse`` (one COO-to-CSR conversion): no quadrature over the whole
mesh. This is the same sum scikit-fem forms, computed faster (side-by-side
timings in ``docs/design/fem.md``); ``tests/test_fem.py`` checks it against
scikit-fem's own global assembly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import ModelError

__all__ = ["Body", "grid_body", "clamp_rows", "tie_rows", "constraint_matrix", "lame_plane"]


@dataclass
class Body:
    """One meshed body: node coordinates, DOF map and its K and M.

    ``p`` is (dim, nnodes); ``nodal_dofs[c, i]`` the global index of component
    ``c`` of node ``i`` inside this body (0-based, before offsetting).
    """

    p: np.ndarray
    nodal_dofs: np.ndarray
    K: sp.csr_matrix
    M: sp.csr_matrix

    @property
    def ndof(self) -> int:
        """Number of DOFs of the body."""
        return self.K.shape[0]


def lame_plane(E: float, nu: float, dim: int):
    r"""Lamé parameters: 3D, or plane stress in 2D (:math:`\lambda^* = E\nu/(1-\nu^2)`)."""
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    mu = E / (2 * (1 + nu))
    if dim == 2:
        lam = 2 * lam * mu / (lam + 2 * mu)
    return lam, mu


def _skfem_parts(dim):
    import skfem as fe
    if dim == 3:
        return fe, fe.MeshHex, fe.ElementVector(fe.ElementHex1())
    return fe, fe.MeshQuad, fe.ElementVector(fe.ElementQuad1())


def _forms():
    import skfem as fe
    from skfem.helpers import ddot, dot, sym_grad, trace

    @fe.BilinearForm
    def stiffness(u, v, w):
        eu, ev = sym_grad(u), sym_grad(v)
        return w["lam"] * trace(eu) * trace(ev) + 2.0 * w["mu"] * ddot(eu, ev)

    @fe.BilinearForm
    def mass(u, v, w):
        return dot(u, v)

    return stiffness, mass


def skfem_matrices(mesh, elem, lam, mu, rho, thickness=1.0):
    """K and M of a whole mesh by scikit-fem's own assembly (reference path; slow at 1e5)."""
    import skfem as fe
    stiffness, mass = _forms()
    basis = fe.Basis(mesh, elem, intorder=2)
    K = stiffness.assemble(basis, lam=lam, mu=mu)
    M = mass.assemble(basis)
    return (thickness * K).tocsr(), (thickness * rho * M).tocsr(), basis


def element_matrices(dim, h, lam, mu, rho, thickness=1.0):
    """(K_e, M_e, local offsets) of one element of sizes ``h`` in scikit-fem's local DOF order."""
    fe, Mesh, elem = _skfem_parts(dim)
    mesh = Mesh.init_tensor(*[np.array([0.0, hi]) for hi in h])
    K, M, basis = skfem_matrices(mesh, elem, lam, mu, rho, thickness)
    ed = basis.element_dofs[:, 0]
    offsets = mesh.p[:, mesh.t[:, 0]] - mesh.p[:, mesh.t[:1, 0]]
    return K.toarray()[np.ix_(ed, ed)], M.toarray()[np.ix_(ed, ed)], offsets


def grid_body(axes, lam, mu, rho, thickness=1.0, *, method="replicate") -> Body:
    """Assemble one body on the tensor grid ``axes`` (one uniform coordinate array per axis).

    ``method="replicate"`` scatters the one-element matrices (fast);
    ``method="skfem"`` lets scikit-fem integrate over the whole mesh (reference).
    Cost of ``replicate``: one COO-to-CSR conversion of the 24^2 (K) and 3 * 8^2 (M)
    entries per hexahedron (2D: 8^2 and 2 * 4^2 per quad), O(nnz log nnz).
    """
    from skfem.assembly import Dofs
    dim = len(axes)
    fe, Mesh, elem = _skfem_parts(dim)
    mesh = Mesh.init_tensor(*axes)
    if method == "skfem":
        K, M, basis = skfem_matrices(mesh, elem, lam, mu, rho, thickness)
        return Body(mesh.p, basis.nodal_dofs, K, M)
    h = [float(a[1] - a[0]) for a in axes]
    Ke, Me, off = element_matrices(dim, h, lam, mu, rho, thickness)
    t = mesh.t
    rel = mesh.p[:, t] - mesh.p[:, t[:1]]  # (dim, nloc, nelem)
    dev = np.max(np.abs(rel - off[:, :, None])) if t.shape[1] else 0.0
    if not dev <= 1e-9 * max(h):
        raise ModelError(f"the grid is not uniform: an element differs from the reference by {dev:.3e}")
    dofs = Dofs(mesh, elem)
    ed = dofs.element_dofs.astype(np.int32)  # (nloc_dof, nelem)
    ndof = int(dofs.N)
    K = _scatter(Ke, ed, ndof)
    M = _scatter(Me, ed, ndof)
    return Body(mesh.p, dofs.nodal_dofs, K, M)


def _scatter(Ae, ed, ndof):
    """Sum of ``Ae`` over the elements whose DOFs are the columns of ``ed``.

    ``Ae`` is symmetrized and only the nonzero entries of its upper triangle are
    scattered, into the global upper triangle (the consistent mass couples no two
    components: 2/3 of M_e is exactly zero); the lower triangle is its transpose,
    so the result is symmetric bit for bit and stores no explicit zeros of M_e.
    """
    Ae = 0.5 * (Ae + Ae.T)
    i, j = np.nonzero(np.triu(Ae))
    r, c = ed[i, :].T.ravel(), ed[j, :].T.ravel()
    data = np.tile(Ae[i, j], ed.shape[1])
    U = sp.csr_matrix((data, (np.minimum(r, c), np.maximum(r, c))), shape=(ndof, ndof))
    U.sum_duplicates()
    A = (U + sp.triu(U, k=1, format="csr").T).tocsr()
    A.sort_indices()
    return A


def clamp_rows(body: Body, offset: int, axis: int, value: float, tol: float):
    """Global DOF indices of the nodes of ``body`` on the plane ``p[axis] == value``."""
    nodes = np.flatnonzero(np.abs(body.p[axis] - value) <= tol)
    return np.sort(body.nodal_dofs[:, nodes].ravel()) + offset


def tie_rows(a: Body, off_a: int, b: Body, off_b: int, axis: int, value: float, tol: float):
    """Pairs (i, j) of global DOFs of coincident nodes of ``a`` and ``b`` on ``p[axis] == value``.

    Every interface node of ``a`` must coincide (within ``tol``) with exactly one
    of ``b`` and vice versa; otherwise :class:`ModelError` (non-matching meshes).
    """
    from scipy.spatial import cKDTree
    na = np.flatnonzero(np.abs(a.p[axis] - value) <= tol)
    nb = np.flatnonzero(np.abs(b.p[axis] - value) <= tol)
    if na.size == 0 or na.size != nb.size:
        raise ModelError(f"tie: the interface has {na.size} nodes on one body and {nb.size} on the other")
    dist, idx = cKDTree(b.p[:, nb].T).query(a.p[:, na].T)
    if np.max(dist) > tol or np.unique(idx).size != idx.size:
        raise ModelError(f"tie: interface nodes do not coincide (largest distance {np.max(dist):.3e})")
    ia = a.nodal_dofs[:, na].T.ravel() + off_a
    ib = b.nodal_dofs[:, nb[idx]].T.ravel() + off_b
    return ia, ib


def constraint_matrix(clamped, tie_a, tie_b, n1):
    r"""G with rows :math:`e_i^T` (clamped DOFs) then :math:`e_a^T - e_b^T` (tied pairs).

    Full row rank by construction, checked structurally: every row owns a column
    no other row touches (a clamped DOF is clamped once; a tie pair's second DOF
    appears in no other row). Refuses input where that fails (:class:`ModelError`).
    """
    clamped = np.asarray(clamped, dtype=np.int64)
    tie_a = np.asarray(tie_a, dtype=np.int64)
    tie_b = np.asarray(tie_b, dtype=np.int64)
    nc, nt = clamped.size, tie_a.size
    owners = np.concatenate([clamped, tie_b])
    if np.unique(owners).size != owners.size or np.intersect1d(tie_b, tie_a).size \
            or np.intersect1d(clamped, tie_b).size:
        raise ModelError("constraints: a clamped DOF is also tied, or a DOF is tied twice")
    rows = np.concatenate([np.arange(nc), nc + np.arange(nt), nc + np.arange(nt)])
    cols = np.concatenate([clamped, tie_a, tie_b])
    vals = np.concatenate([np.ones(nc), np.ones(nt), -np.ones(nt)])
    return sp.csr_matrix((vals, (rows, cols)), shape=(nc + nt, n1))
