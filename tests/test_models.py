"""Index3Model, generators, catalog and the M.E.S.S. loader against
independent references (models.md)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import morsuite as ms
from morsuite.errors import DtypeWarning
from morsuite.models import Index3Model
from support import assert_rounding, condest, rounding_unit, solve_tolerance

IMAG_POINTS = 1j * np.logspace(-3, 1, 20)
COMPLEX_POINTS = np.array([0.3 + 0.2j, -0.05 + 1j, 2.0])


def rel_err(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def dense(X):
    return X.toarray() if sp.issparse(X) else np.asarray(X)


def nullspace_transfer(fom, s):
    """T(s) = L Z (s^2 Z'MZ + s Z'DZ + Z'KZ)^-1 Z'F with an explicit orthonormal
    basis Z of ker G: an independent route that never touches the saddle point matrix."""
    M, D, K = dense(fom.M), dense(fom.D), dense(fom.K)
    Z = sla.null_space(dense(fom.G)) if fom.n2 else np.eye(fom.n1)
    assert Z.shape == (fom.n1, fom.n1 - fom.n2)
    A = s * s * (Z.T @ M @ Z) + s * (Z.T @ D @ Z) + Z.T @ K @ Z
    return fom.L @ Z @ np.linalg.solve(A, Z.T @ fom.F)


# ---------------------------------------------------------------------------
# M.E.S.S. files: loader, generator, first-order realization
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def mess_loaded(mess_file):
    g, path, raw = mess_file
    return g, raw, ms.models.load_mat(path)


def test_load_mat_matches_file_realization(mess_loaded):
    """L x from the saddle-point solve equals C (sE - A)^-1 B of the file's own
    first-order realization (scipy spsolve on the pencil)."""
    g, raw, fom = mess_loaded
    E, A = sp.csc_matrix(raw["E"]), sp.csc_matrix(raw["A"])
    B, C = dense(raw["B"]).astype(complex), sp.csr_matrix(raw["C"])
    assert E.shape == (2 * g + 1, 2 * g + 1)
    assert (fom.n1, fom.n2, fom.m, fom.p) == (g, 1, 1, 3)
    worst = 0.0  # the worst ratio of the difference to its rounding level (support.condest)
    for s in np.concatenate([IMAG_POINTS, COMPLEX_POINTS]):
        ref = C @ spla.spsolve(sp.csc_matrix(s * E - A), B).reshape(-1, 1)
        T = fom.transfer(s)
        assert T.shape == (3, 1)
        worst = max(worst, rel_err(T, ref) / (rounding_unit(E.shape[0]) * condest(s * E - A)))
    # measured: errors <= 1.4e-14 against rounding levels 7e-12 .. 8e-9 (largest at the resonances),
    # the worst ratio 2e-4 (bound 1)
    assert_rounding(worst, 1.0, "transfer against the file's realization / its rounding level")


def test_dsms_generator_equals_file(mess_loaded):
    g, raw, fom = mess_loaded
    gen = ms.models.dsms(g)
    for key in ("M", "D", "K", "G"):
        X, Y = getattr(gen, key), getattr(fom, key)
        assert X.shape == Y.shape
        assert X.nnz == Y.nnz, key
        assert abs(X - Y).max() == 0, key
    assert np.array_equal(gen.F, fom.F)
    assert np.array_equal(gen.L, fom.L)
    # and the file's negated D and K are the physical ones, negated
    assert abs(gen.K + sp.csr_matrix(raw["K"])).max() == 0
    assert abs(gen.D + sp.csr_matrix(raw["D"])).max() == 0


def test_first_order_realization_equals_file(mess_loaded):
    g, raw, fom = mess_loaded
    E, A, B, C = fom.first_order()
    assert abs(E - sp.csr_matrix(raw["E"])).max() == 0
    assert abs(A - sp.csr_matrix(raw["A"])).max() == 0
    assert np.array_equal(B, dense(raw["B"]))
    assert np.array_equal(C, dense(raw["C"]))


def test_dsms_physical_structure():
    fom = ms.models.dsms(10)
    K, D = fom.K.toarray(), fom.D.toarray()
    assert np.array_equal(np.diag(K), [6.0] * 10)
    assert np.array_equal(np.diag(K, 1), [-2.0] * 9)
    assert np.allclose(D, 2.5 * K, rtol=0, atol=0)
    assert np.array_equal(fom.M.toarray(), 100 * np.eye(10))
    assert np.array_equal(fom.G.toarray(), [[1] + [0] * 8 + [-1]])


def test_dsms_sigma_values_models_md():
    """models.md: sigma_max 0.10880 at w = 0.01, 5.254e-3 at w = 1 (g = 600)."""
    fom = ms.models.dsms(600)
    s = ms.analysis.sigma_max(fom.freqresp([1e-2, 1.0]))
    assert s[0] == pytest.approx(0.10880, abs=6e-6)
    assert s[1] == pytest.approx(5.254e-3, abs=6e-7)


# ---------------------------------------------------------------------------
# TCOM
# ---------------------------------------------------------------------------

def test_tcom_sizes(tcom2000):
    assert (tcom2000.n1, tcom2000.n2, tcom2000.m, tcom2000.p) == (6001, 6, 1, 1)


@pytest.mark.parametrize("omega, ref, rtol", [
    (1e-3, 6.7450021e7, 1e-7),
    (1e-2, 2.8126819e7, 1e-7),
    (1e-1, 3.638118e5, 2e-7),     # 7 digits given
    (1.0, 3672.937, 2e-7),
    (6.594e-3, 3.282604e7, 2e-7),
])
def test_tcom_reference_sigma(tcom2000, omega, ref, rtol):
    s = ms.analysis.sigma_max(tcom2000.freqresp([omega]))[0]
    assert s == pytest.approx(ref, rel=rtol)


def test_tcom_reference_dc_gain(tcom2000):
    T0 = tcom2000.transfer(0.0)
    assert T0.shape == (1, 1)
    assert abs(T0[0, 0].imag) == 0
    assert T0[0, 0].real == pytest.approx(1.9354132e8, rel=1e-7)


def test_tcom_structure():
    nc = 4
    fom = ms.models.tcom(nc=nc)
    K = fom.K.toarray()
    c = 3 * nc
    assert np.allclose(K, K.T)
    assert K[c, c] == 10 + 20 + 1 + 50
    assert K[nc - 1, c] == -10 and K[2 * nc - 1, c] == -20 and K[3 * nc - 1, c] == -1
    assert np.array_equal(np.diag(fom.M.toarray()), [1] * nc + [2] * nc + [3] * nc + [10])
    Dv = fom.D.toarray() - 0.01 * (fom.M.toarray() + K)
    assert np.allclose(Dv, np.diag(np.isin(np.arange(3 * nc + 1), [0, nc - 1, 2 * nc]) * 5.0))
    G = fom.G.toarray()
    assert G.shape == (6, 3 * nc + 1)
    assert np.array_equal(np.nonzero(G)[1], [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11])
    assert np.array_equal(G.sum(axis=1), np.zeros(6))
    assert np.array_equal(fom.F, np.ones((3 * nc + 1, 1)))
    assert ms.models.tcom(nc=4, constrained=False).n2 == 0


# ---------------------------------------------------------------------------
# transfer against an explicit null-space basis (independent of the saddle solve)
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("s", [0.01j, 0.2j, 1.5j, 0.05 + 0.3j, 0.4])
def test_tcom_transfer_vs_nullspace(tcom20, s):
    assert rel_err(tcom20.transfer(s), nullspace_transfer(tcom20, s)) < 1e-10


@pytest.mark.parametrize("s", [0.01j, 0.16j, 1j, -0.02 + 0.5j, 0.7, 0.0])
def test_dsms_transfer_vs_nullspace(dsms50, s):
    assert rel_err(dsms50.transfer(s), nullspace_transfer(dsms50, s)) < 1e-10


@pytest.mark.parametrize("s", [0.1j, 1 + 1j, 0.3])
def test_random_mimo_transfer_vs_nullspace(small_random, s):
    assert rel_err(small_random.transfer(s), nullspace_transfer(small_random, s)) < 1e-10


def test_unconstrained_model_transfer(make_random_model):
    fom = make_random_model(n1=8, n2=0, m=2, p=2)
    assert fom.n2 == 0
    s = 0.3 + 0.7j
    P = s * s * dense(fom.M) + s * dense(fom.D) + dense(fom.K)
    ref = fom.L @ np.linalg.solve(P, fom.F)
    assert_rounding(rel_err(fom.transfer(s), ref), solve_tolerance(P), "transfer")  # measured 2e-16, bound 2e-14


def test_real_model_conjugate_symmetry(dsms50):
    s = 0.02 + 0.3j
    # the conjugate view of the same LU: exact conjugates (measured 0), not a second solve
    assert np.allclose(dsms50.transfer(np.conj(s)), np.conj(dsms50.transfer(s)), rtol=1e-13, atol=0)


def test_transfer_bad_shift(dsms50):
    with pytest.raises(ms.InputError, match="s must"):
        dsms50.transfer("x")
    with pytest.raises(ms.InputError, match="s must be finite"):
        dsms50.transfer(np.inf)
    with pytest.raises(ms.InputError, match="s must be finite"):
        dsms50.transfer(complex(0, np.nan))


# ---------------------------------------------------------------------------
# derivative
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("model", ["dsms50", "tcom20", "small_random"])
@pytest.mark.parametrize("s", [0.1j, 0.05 + 0.4j, 0.8])
def test_transfer_derivative_vs_finite_difference(request, model, s):
    fom = request.getfixturevalue(model)
    dT = fom.transfer(s, derivative=True)
    assert dT.shape == (fom.p, fom.m)
    h = 1e-5 * abs(s)
    # T is analytic: central differences along the real and imaginary axes agree with T'
    fd_re = (fom.transfer(s + h) - fom.transfer(s - h)) / (2 * h)
    fd_im = (fom.transfer(s + 1j * h) - fom.transfer(s - 1j * h)) / (2j * h)
    assert rel_err(dT, fd_re) < 1e-6
    assert rel_err(dT, fd_im) < 1e-6


def test_derivative_conjugate_shift_uses_cached_lu(dsms50):
    s = 0.03 + 0.2j
    d1 = dsms50.transfer(s, derivative=True)
    n = dsms50.solver.stats.factorizations
    d2 = dsms50.transfer(np.conj(s), derivative=True)
    assert dsms50.solver.stats.factorizations == n
    assert np.allclose(d2, np.conj(d1), rtol=1e-13, atol=0)  # the conjugate view: measured 0


# ---------------------------------------------------------------------------
# freqresp and sigma_max
# ---------------------------------------------------------------------------

def test_freqresp_shape_and_stacked_transfer(small_random):
    omega = np.logspace(-2, 1, 7)
    H = small_random.freqresp(omega)
    assert H.shape == (7, small_random.p, small_random.m) == (7, 3, 2)
    assert H.dtype == complex
    ref = np.stack([small_random.transfer(1j * w) for w in omega])
    assert np.allclose(H, ref, rtol=1e-13, atol=0)  # the same solves, one per frequency: measured 0
    assert small_random.last_freqresp_stats["factorizations"] == 7


def test_freqresp_scalar_and_list(dsms50):
    assert dsms50.freqresp(0.1).shape == (1, 3, 1)
    assert dsms50.freqresp([0.1, 0.2]).shape == (2, 3, 1)


@pytest.mark.parametrize("omega, match", [
    ([], "non-empty"),
    (np.ones((2, 2)), "1-D"),
    ([0.1j], "real"),
    ([0.1, np.nan], "non-finite"),
    (["a"], "real"),
])
def test_freqresp_bad_omega(dsms50, omega, match):
    with pytest.raises(ms.InputError, match=match):
        dsms50.freqresp(omega)


@pytest.mark.parametrize("model", ["dsms50", "small_random"])
def test_sigma_max_agrees_with_svd(request, model):
    fom = request.getfixturevalue(model)
    H = fom.freqresp(np.logspace(-2, 0, 5))
    ref = np.array([np.linalg.svd(h, compute_uv=False)[0] for h in H])
    # sigma_max is perfectly conditioned (Weyl: |d sigma| <= ||dH||): measured 2e-16 relative
    assert np.allclose(ms.analysis.sigma_max(H), ref, rtol=1e-13, atol=0)
    assert ms.analysis.sigma_max(H[0]) == pytest.approx(ref[0], rel=1e-13)


def test_sigma_max_bad_shape():
    with pytest.raises(ms.InputError, match="H must"):
        ms.analysis.sigma_max(np.ones(3))


# ---------------------------------------------------------------------------
# Index3Model validation: one bad input per test
# ---------------------------------------------------------------------------

def build(parts, **changes):
    kw = {k: changes.pop(k) for k in list(changes) if k in ("band", "name", "check_constraints")}
    p = dict(parts)
    p.update(changes)
    return Index3Model(p["M"], p["D"], p["K"], p["G"], p["F"], p["L"], **kw)


def test_valid_parts_build(valid_parts):
    fom = build(valid_parts)
    assert (fom.n1, fom.n2, fom.m, fom.p, fom.order) == (6, 1, 1, 2, 5)
    assert fom.summary()["first_order_states"] == 13


def test_error_hierarchy():
    assert issubclass(ms.ShapeError, ms.InputError)
    assert issubclass(ms.ModelError, ms.InputError)
    assert issubclass(ms.InputError, ms.MorsuiteError)
    assert issubclass(ms.InputError, ValueError)
    assert issubclass(ms.SingularShiftError, ms.MorsuiteError)


def test_nonsquare_M(valid_parts):
    with pytest.raises(ms.ShapeError, match=r"matrix M must be square"):
        build(valid_parts, M=sp.csr_matrix(np.ones((6, 5))))


def test_M_missing(valid_parts):
    with pytest.raises(ms.InputError, match=r"matrix M is missing"):
        build(valid_parts, M=None)


def test_D_wrong_shape(valid_parts):
    with pytest.raises(ms.ShapeError, match=r"matrix D has shape \(5, 5\)"):
        build(valid_parts, D=sp.identity(5))


def test_K_wrong_shape(valid_parts):
    with pytest.raises(ms.ShapeError, match=r"matrix K has shape"):
        build(valid_parts, K=sp.identity(7))


def test_G_wrong_columns(valid_parts):
    with pytest.raises(ms.ShapeError, match=r"matrix G has 5 columns"):
        build(valid_parts, G=sp.csr_matrix(([1.0, -1.0], ([0, 0], [0, 4])), shape=(1, 5)))


def test_n2_not_less_than_n1(valid_parts):
    with pytest.raises(ms.ShapeError, match=r"matrix G has n2 = 6 rows"):
        build(valid_parts, G=sp.identity(6))


def test_F_wrong_rows(valid_parts):
    with pytest.raises(ms.ShapeError, match=r"matrix F has 5 rows"):
        build(valid_parts, F=np.ones((5, 1)))


def test_L_wrong_columns(valid_parts):
    with pytest.raises(ms.ShapeError, match=r"matrix L has 7 columns"):
        build(valid_parts, L=np.ones((1, 7)))


def test_F_without_columns(valid_parts):
    with pytest.raises(ms.ShapeError, match=r"at least one input"):
        build(valid_parts, F=np.ones((6, 0)))


def test_1d_F_and_L_are_one_input_and_output(valid_parts):
    fom = build(valid_parts, F=np.ones(6), L=np.arange(6.0))
    assert fom.F.shape == (6, 1) and fom.L.shape == (1, 6)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("name", ["M", "D", "K", "G", "F", "L"])
def test_nonfinite_entry(valid_parts, name, bad):
    X = valid_parts[name]
    X = X.tolil(copy=True) if sp.issparse(X) else X.copy()
    X[0, 0] = bad
    X = X.tocsr() if sp.issparse(X) else X
    with pytest.raises(ms.InputError, match=rf"matrix {name} has non-finite"):
        build(valid_parts, **{name: X})


def test_G_zero_row(valid_parts):
    G = sp.csr_matrix(np.vstack([valid_parts["G"].toarray(), np.zeros((1, 6))]))
    with pytest.raises(ms.ModelError, match=r"matrix G has zero rows \[1\]"):
        build(valid_parts, G=G)


def test_G_zero_row_explicit_zero_entry(valid_parts):
    G = sp.csr_matrix((np.array([1.0, -1.0, 0.0]), (np.array([0, 0, 1]), np.array([0, 5, 2]))),
                      shape=(2, 6))
    assert G.nnz == 3
    with pytest.raises(ms.ModelError, match=r"matrix G has zero rows"):
        build(valid_parts, G=G)


def test_G_rank_deficient_equal_rows(valid_parts):
    G = sp.csr_matrix(np.vstack([valid_parts["G"].toarray()] * 2))
    with pytest.raises(ms.ModelError, match=r"G .*rank deficient"):
        build(valid_parts, G=G)


def test_G_rank_deficient_combination(valid_parts):
    g = np.array([[1.0, 0, 0, 0, 0, -1], [0, 1, 0, 0, -1, 0]])
    G = np.vstack([g, g[0] + 2 * g[1]])
    with pytest.raises(ms.ModelError, match=r"G .*rank deficient"):
        build(valid_parts, G=G)


def test_G_rank_check_can_be_skipped(valid_parts):
    G = sp.csr_matrix(np.vstack([valid_parts["G"].toarray()] * 2))
    fom = build(valid_parts, G=G, check_constraints=False)
    assert fom.n2 == 2


def test_complex_with_imaginary_part_refused(valid_parts):
    with pytest.raises(ms.InputError, match=r"matrix K is complex with a nonzero imaginary part"):
        build(valid_parts, K=valid_parts["K"] * (1 + 1e-3j))


def test_complex_dense_F_with_imaginary_part_refused(valid_parts):
    with pytest.raises(ms.InputError, match=r"matrix F is complex"):
        build(valid_parts, F=valid_parts["F"] + 1j)


def test_complex_with_zero_imaginary_part_converted(valid_parts):
    with pytest.warns(DtypeWarning, match=r"matrix M is complex with zero imaginary part"):
        fom = build(valid_parts, M=valid_parts["M"].astype(complex))
    assert fom.M.dtype == np.float64
    assert abs(fom.M - valid_parts["M"]).max() == 0


def test_dtype_warning_is_a_morsuite_warning():
    assert issubclass(DtypeWarning, ms.MorsuiteWarning)


def test_integer_dtype_converted(valid_parts):
    Mi = (valid_parts["M"].toarray()).astype(np.int64)
    Fi = valid_parts["F"].astype(np.int32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fom = build(valid_parts, M=Mi, F=Fi)
    assert fom.M.dtype == np.float64 and fom.F.dtype == np.float64
    assert np.array_equal(fom.M.toarray(), Mi)


def test_bool_dtype_converted(valid_parts):
    fom = build(valid_parts, F=valid_parts["F"].astype(bool))
    assert fom.F.dtype == np.float64 and fom.F[0, 0] == 1.0


def test_object_dtype_refused(valid_parts):
    with pytest.raises(ms.InputError, match=r"matrix F has dtype object"):
        build(valid_parts, F=np.array([[None]] * 6, dtype=object))


def test_string_dtype_refused(valid_parts):
    with pytest.raises(ms.InputError, match=r"matrix L has non-numeric dtype"):
        build(valid_parts, L=np.array([["a"] * 6]))


def test_ragged_input_refused(valid_parts):
    with pytest.raises(ms.InputError, match=r"matrix M"):
        build(valid_parts, M=[[1.0, 2.0], [3.0]])


def test_3d_input_refused(valid_parts):
    with pytest.raises(ms.InputError, match=r"matrix M"):
        build(valid_parts, M=np.ones((6, 6, 1)))


def test_dense_matrices_converted_to_sparse(valid_parts):
    fom = build(valid_parts, **{k: valid_parts[k].toarray() for k in ("M", "D", "K", "G")})
    for key in ("M", "D", "K", "G"):
        assert sp.issparse(getattr(fom, key)), key
        assert abs(getattr(fom, key) - valid_parts[key]).max() == 0
    assert isinstance(fom.F, np.ndarray) and isinstance(fom.L, np.ndarray)


def test_sparse_F_converted_to_dense(valid_parts):
    fom = build(valid_parts, F=sp.csr_matrix(valid_parts["F"]))
    assert isinstance(fom.F, np.ndarray) and np.array_equal(fom.F, valid_parts["F"])


@pytest.mark.parametrize("band", [(1.0, 0.1), (0.0, 1.0), (-1.0, 1.0), (0.1, np.inf), (0.1, 0.1),
                                  (np.nan, 1.0)])
def test_bad_band(valid_parts, band):
    with pytest.raises(ms.InputError, match=r"band"):
        build(valid_parts, band=band)


def test_inputs_not_mutated(valid_parts):
    copies = {k: (v.copy()) for k, v in valid_parts.items()}
    fom = build(valid_parts)
    fom.transfer(0.1j)
    fom.freqresp([0.1, 0.2])
    for k, v in valid_parts.items():
        if sp.issparse(v):
            assert abs(v - copies[k]).max() == 0
        else:
            assert np.array_equal(v, copies[k])


@pytest.mark.parametrize("band", [(1.0, 2.0, 3.0), 1.0, ("a", "b"), None])
def test_band_not_a_pair(valid_parts, band):
    with pytest.raises(ms.InputError, match=r"band must be a pair"):
        build(valid_parts, band=band)


def test_unsorted_csr_input_not_mutated(valid_parts):
    """A CSR input with unsorted column indices is left as the caller made it."""
    K = valid_parts["K"].tocsr()
    data, ind = K.data.copy(), K.indices.copy()
    for i in range(K.shape[0]):  # reverse the entries within each row
        a, b = K.indptr[i], K.indptr[i + 1]
        data[a:b], ind[a:b] = data[a:b][::-1], ind[a:b][::-1]
    Ku = sp.csr_matrix((data, ind, K.indptr.copy()), shape=K.shape)
    assert not Ku.has_sorted_indices
    keep = (Ku.data.copy(), Ku.indices.copy())
    fom = build(valid_parts, K=Ku)
    assert np.array_equal(Ku.data, keep[0]) and np.array_equal(Ku.indices, keep[1])
    assert abs(fom.K - K).max() == 0


def test_model_does_not_alias_caller_arrays(valid_parts):
    """Editing the arrays passed in afterwards must not change the model
    (its cached solver would silently go stale)."""
    parts = {k: v.copy() for k, v in valid_parts.items()}
    fom = build(parts)
    T = fom.transfer(0.1j)
    parts["K"].data *= 2
    parts["M"].data[:] = 1.0
    parts["F"][:] = 7.0
    parts["L"][:] = 3.0
    assert abs(fom.K - valid_parts["K"]).max() == 0 and abs(fom.M - valid_parts["M"]).max() == 0
    assert np.array_equal(fom.F, valid_parts["F"]) and np.array_equal(fom.L, valid_parts["L"])
    assert np.array_equal(build(valid_parts).transfer(0.1j), T)


def test_with_io(dsms50):
    red = dsms50.with_io(L=dsms50.L[:1], name="one output")
    assert red.p == 1 and red.name == "one output"
    assert np.allclose(red.transfer(0.1j), dsms50.transfer(0.1j)[:1], rtol=1e-14, atol=0)  # same solve: measured 0


# ---------------------------------------------------------------------------
# generators and catalog
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("g, match", [
    (0, r"\bg must be finite and >= 4"),
    (-5, r"\bg must be"),
    (3, r"\bg must be finite and >= 4"),
    (2.5, r"\bg must be an integer"),
    (600.0, r"\bg must be an integer"),
    ("600", r"\bg must be an integer"),
    (True, r"\bg must be an integer"),
    (None, r"\bg must be an integer"),
])
def test_dsms_bad_g(g, match):
    with pytest.raises(ms.InputError, match=match):
        ms.models.dsms(g)


@pytest.mark.parametrize("kw, match", [
    ({"mass": 0.0}, r"\bmass must"),
    ({"mass": np.nan}, r"\bmass must"),
    ({"k": -1.0}, r"\bk must"),
    ({"delta": np.inf}, r"\bdelta must"),
])
def test_dsms_bad_physical_parameters(kw, match):
    with pytest.raises(ms.InputError, match=match):
        ms.models.dsms(10, **kw)


def test_dsms_numpy_integer_g():
    assert ms.models.dsms(np.int64(10)).n1 == 10


@pytest.mark.parametrize("nc, match", [
    (21, r"\bnc must be even"),
    (0, r"\bnc must be finite"),
    (1, r"\bnc must be finite and >= 2"),
    (2.0, r"\bnc must be an integer"),
])
def test_tcom_bad_nc(nc, match):
    with pytest.raises(ms.InputError, match=match):
        ms.models.tcom(nc=nc)


def test_tcom_odd_nc_unconstrained_ok():
    fom = ms.models.tcom(nc=5, constrained=False)
    assert (fom.n1, fom.n2) == (16, 0)


@pytest.mark.parametrize("kw, match", [
    ({"masses": (1.0, 2.0)}, r"masses and stiffness"),
    ({"stiffness": (1.0, -2.0, 3.0)}, r"stiffness\[1\] must"),
    ({"central_mass": 0}, r"central_mass must"),
    ({"alpha": -0.1}, r"alpha must"),
])
def test_tcom_bad_parameters(kw, match):
    with pytest.raises(ms.InputError, match=match):
        ms.models.tcom(nc=4, **kw)


def test_catalog_available():
    assert {"dsms", "tcom"} <= set(ms.models.available())


def test_catalog_get():
    fom = ms.models.get("dsms", g=20)
    assert fom.n1 == 20 and fom.band == (1e-2, 1.0)
    assert ms.models.get("tcom", nc=4).band == (1e-3, 1.0)


def test_catalog_unknown_model_lists_valid():
    with pytest.raises(ms.InputError, match=r"unknown model 'nope'.*dsms.*tcom"):
        ms.models.get("nope")


def test_catalog_unknown_parameter_lists_valid():
    with pytest.raises(ms.InputError, match=r"no parameter 'h'.*valid: g, mass"):
        ms.models.get("dsms", h=3)


def test_parse_spec():
    fom = ms.models.parse("dsms:g=600")
    assert fom.n1 == 600 and fom.n2 == 1
    ref = ms.models.dsms(600)
    assert abs(fom.K - ref.K).max() == 0


def test_parse_spec_multiple_and_types():
    fom = ms.models.parse("tcom:nc=4,alpha=0.02,constrained=false")
    assert fom.n2 == 0
    ref = ms.models.tcom(nc=4, alpha=0.02, constrained=False)
    assert abs(fom.D - ref.D).max() == 0
    fom = ms.models.parse("tcom:nc=4,stiffness=1;2;3")
    assert abs(fom.K - ms.models.tcom(nc=4, stiffness=(1, 2, 3)).K).max() == 0


def test_parse_name_only():
    assert ms.models.parse("tcom").n1 == 6001


def test_parse_missing_value():
    with pytest.raises(ms.InputError, match=r"expected key=value, got 'g'"):
        ms.models.parse("dsms:g")


@pytest.mark.parametrize("spec", ["", None, 3])
def test_parse_not_a_string(spec):
    with pytest.raises(ms.InputError, match=r"model spec"):
        ms.models.parse(spec)


def test_parse_bad_value_reaches_generator():
    with pytest.raises(ms.InputError, match=r"\bg must be an integer"):
        ms.models.parse("dsms:g=2.5")


def test_parse_mat_path(data_dir):
    fom = ms.models.parse(str(data_dir / "mess_msd_ind3_g600.mat"))
    assert fom.n1 == 600


@pytest.mark.parametrize("constraints, n2", [("curvature", 3), ("averaging", 3), ("pairs", 6)])
@pytest.mark.parametrize("io", ["sum", "chains", "points"])
def test_tcom_variants_transfer_vs_nullspace(constraints, n2, io):
    """The constraint and input/output variants of the TCOM family: sizes, G x = 0 for the
    defining pattern of each row, and T(s) against the dense null-space evaluation."""
    nc = 10
    fom = ms.models.tcom(nc=nc, constraints=constraints, io=io)
    m = 1 if io == "sum" else 3
    assert (fom.n1, fom.n2, fom.m, fom.p) == (3 * nc + 1, n2, m, m)
    G = fom.G.toarray()
    if constraints == "curvature":
        x = np.arange(fom.n1, dtype=float)  # linear in each chain: zero curvature everywhere
        assert np.allclose(G @ x, 0)
    if constraints == "averaging":
        x = np.ones(fom.n1)  # a constant chain sits at its mean
        assert np.allclose(G @ x, 0)
    if io == "chains":
        assert np.array_equal(fom.F.sum(axis=0), [nc, nc, nc]) and np.array_equal(fom.L, fom.F.T)
        assert fom.F[-1].sum() == 0  # the central mass is not driven
    if io == "points":
        assert np.array_equal(np.flatnonzero(fom.F.sum(axis=1)), [2, 12, 22])
        assert np.array_equal(np.flatnonzero(fom.L.sum(axis=0)), [7, 17, 27])
    for s in (0.05j, 0.3 + 0.7j):
        assert rel_err(fom.transfer(s), nullspace_transfer(fom, s)) < 1e-10
    assert "constraints=" in fom.name or constraints == "pairs"


def test_tcom_variant_bad_options():
    with pytest.raises(ms.InputError, match="constraints"):
        ms.models.tcom(nc=4, constraints="bogus")
    with pytest.raises(ms.InputError, match="io"):
        ms.models.tcom(nc=4, io="mimo")
    assert ms.models.parse("tcom:nc=6,constraints=curvature,io=chains").m == 3
