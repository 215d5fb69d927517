"""Sparse LU backends (morsuite.linalg.backends): agreement with SuperLU and dense solves, the
structural choice, the forced option, its record in info, determinism, shift-parallel executors."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp

import morsuite as ms
from morsuite.linalg import SaddlePointSolver
from morsuite.linalg.backends import BAND_RULE, choose
from morsuite.utils import blas_threads
from support import assert_rounding, rounding_unit, solve_tolerance

BACKENDS = ("superlu", "banded")
SHIFTS = (0.0, 0.3j, 1.0 + 2.0j, 1e-3j, 5.0)


def grid3d_model(n=7):
    """A 3D 7-point stencil 'elastic' model (n^3 positions) clamped on one face by constraints:
    its RCM bandwidth (about 2 n^2) is far above the banded rule."""
    T = sp.diags([-np.ones(n - 1), 2 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    I = sp.identity(n)
    K = (sp.kron(sp.kron(T, I), I) + sp.kron(sp.kron(I, T), I) + sp.kron(sp.kron(I, I), T)).tocsr()
    n1 = n ** 3
    M = sp.identity(n1, format="csr")
    face = np.arange(n * n)  # the x = 0 face
    G = sp.csr_matrix((np.ones(face.size), (np.arange(face.size), face)), shape=(face.size, n1))
    rng = np.random.default_rng(1)
    return ms.models.Index3Model(M, 0.01 * K + 0.1 * M, K, G, rng.standard_normal((n1, 1)),
                                 rng.standard_normal((1, n1)), name="grid3d")


def _dense(fom, s):
    A = (s * s * fom.M + s * fom.D + fom.K).toarray()
    G = fom.G.toarray()
    return np.block([[A, G.T], [G, np.zeros((fom.n2, fom.n2))]])


@pytest.mark.parametrize("which", ["dsms", "tcom", "random", "grid3d"])
def test_backends_agree_with_dense_solves(which, dsms50, tcom20, small_random):
    """Solve and transposed solve of every backend: backward error ~1e-16 and the dense solution."""
    fom = {"dsms": dsms50, "tcom": tcom20, "random": small_random, "grid3d": grid3d_model(5)}[which]
    rng = np.random.default_rng(0)
    N = fom.n1 + fom.n2
    B = rng.standard_normal((N, 2)) + 1j * rng.standard_normal((N, 2))
    for backend in BACKENDS:
        solver = fom.new_solver(backend=backend)
        assert solver.backend == backend
        with blas_threads(1):  # small dense solves: threads only add synchronisation on a loaded machine
            _check_solves(fom, solver, B)
        assert solver.stats.refactorizations == 0


def _check_solves(fom, solver, B):
    backend = solver.backend
    for s in SHIFTS:
        S = _dense(fom, s)
        tol = solve_tolerance(S)  # measured <= 7e-16, bounds >= 4e-13
        f = solver.factor(s)
        for trans in (False, True):
            x = f.solve(B, trans=trans, full=True)
            ref = np.linalg.solve(S.T if trans else S, B)
            assert_rounding(np.linalg.norm(x - ref) / np.linalg.norm(ref), tol, f"{backend} s={s} trans={trans}")
            # 10 for the element growth that threshold pivoting allows (KLU's, the banded LU's within
            # blocks); measured <= 1e-15 (KLU, random model, s = 5), bound 8e-14
            assert_rounding(f.backward_error(B, trans=trans), 10 * rounding_unit(S.shape[0]),
                            f"{backend} backward error s={s} trans={trans}")
        g = solver.factor(np.conj(s))  # the conjugate view of the same factors
        Sc = _dense(fom, np.conj(s))
        ref = np.linalg.solve(Sc, B)
        assert_rounding(np.linalg.norm(g.solve(B, full=True) - ref) / np.linalg.norm(ref), tol, f"{backend} conjugate")


def test_auto_choice_is_structural_and_recorded(dsms50, tcom20):
    """Chains get the banded LU (the TCOM's border of 6 rows KLU where installed, from BAND_RULE's
    klu_min_n rows on), a small 3D grid SuperLU; the analysis is plain data on the model."""
    from morsuite.linalg.backends_ext import available
    big_enough = tcom20.n1 + tcom20.n2 >= BAND_RULE["klu_min_n"]
    for fom, kl_ku, want in ((dsms50, (1, 1), "banded"),
                             (tcom20, (2, 2), "klu" if available()["klu"] and big_enough else "banded")):
        a = fom.lu_analysis()
        assert a["backend"] == want and (a["kl"], a["ku"]) == kl_ku and a["requested"] == "auto"
    g = grid3d_model(7)
    a = g.lu_analysis()
    assert a["backend"] == "superlu" and a["kl"] + a["ku"] > BAND_RULE["max_band"]
    assert choose(a["kl"], a["ku"], 0)[0] == "superlu"
    assert choose(1, 1, BAND_RULE["max_border"] + 1, available={"klu": False, "pardiso": False})[0] == "superlu"


def test_forced_backend_and_bad_name(dsms50, monkeypatch):
    dsms50.lu_backend = "superlu"
    assert dsms50.solver.backend == "superlu" and dsms50.new_solver().backend == "superlu"
    res = ms.reducers.make("irka", dsms50).reduce(4)
    assert res.info["lu_backend"]["backend"] == "superlu" and res.info["lu_backend"]["reason"] == "forced"
    with pytest.raises(ms.MorsuiteError, match="backend"):
        dsms50.lu_backend = "mumps"
    with pytest.raises(ms.MorsuiteError, match="backend"):
        SaddlePointSolver(dsms50.M, dsms50.D, dsms50.K, dsms50.G, backend="banded", scaling="ruiz")
    monkeypatch.setenv("MORSUITE_LU_BACKEND", "superlu")  # overrides "auto" only
    assert ms.models.dsms(g=50).lu_analysis()["backend"] == "superlu"


def _tf_rel_diff(a, b, omega):
    Ha, Hb = a.freqresp(omega), b.freqresp(omega)
    return float(np.max(np.abs(Ha - Hb)) / np.max(np.abs(Hb)))


@pytest.mark.parametrize("which", ["dsms", "tcom"])
def test_roms_of_every_backend_agree_with_superlu(which):
    """Converged IRKA reduced models from the banded backend and from SuperLU: the same
    transfer function to 1e-8 relative."""
    make = (lambda: ms.models.dsms(g=400)) if which == "dsms" else (lambda: ms.models.tcom(nc=200))
    omega = np.logspace(-2, 1, 60)
    roms = {}
    for backend in BACKENDS:
        fom = make()
        fom.lu_backend = backend
        res = ms.reducers.make("irka", fom).reduce(6)
        assert res.info["converged"] and res.info["lu_backend"]["backend"] == backend
        roms[backend] = res.rom
    assert _tf_rel_diff(roms["banded"], roms["superlu"], omega) < 1e-8


def _after_other_runs(backend):
    """tcom(nc=200) with ``backend`` on which an IRKA run (r = 4, 3 iterations) and a transfer
    function evaluation have already run."""
    used = ms.models.tcom(nc=200)
    used.lu_backend = backend
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ms.reducers.make("irka", used, maxit=3).reduce(4)
        used.transfer(0.7j)
    return used


@pytest.mark.parametrize("backend", BACKENDS)
def test_same_rom_on_a_fresh_model_and_after_another_run(backend):
    """A reduction does not depend on what ran before on the same model object: the
    ordering is found from the pattern alone, so every LU, the first included, is the same.
    Determinism means the same bits here (same operations in the same order)."""
    fresh = ms.models.tcom(nc=200)
    fresh.lu_backend = backend
    ref = ms.reducers.make("irka", fresh).reduce(6)
    again = ms.reducers.make("irka", _after_other_runs(backend)).reduce(6)
    assert again.info["iterations"] == ref.info["iterations"]
    for k in ("M", "D", "K", "F", "L"):
        assert np.array_equal(getattr(again.rom, k), getattr(ref.rom, k)), k


def test_shift_parallel_threads_give_the_same_rom():
    """Two solver threads: the same bases (jobs are deterministic, vectors made in shift order)."""
    fom = ms.models.tcom(nc=200)
    one = ms.reducers.make("irka", fom, solver_threads=1).reduce(8)
    two = ms.reducers.make("irka", fom, solver_threads=2).reduce(8)
    assert one.info["solver_threads"] == 1 and two.info["solver_threads"] == 2
    assert one.info["lu_count"] == two.info["lu_count"]
    for k in ("M", "D", "K", "F", "L"):
        assert np.array_equal(getattr(one.rom, k), getattr(two.rom, k)), k


def test_dask_executor_on_a_local_cluster():
    """executor='dask': the jobs run on a LocalCluster's worker process; same ROM, LUs counted."""
    distributed = pytest.importorskip("distributed")
    fom = ms.models.dsms(g=300)
    ref = ms.reducers.make("irka", fom, solver_threads=1).reduce(4)
    with pytest.raises(ms.MorsuiteError, match="Client"):
        ms.reducers.make("irka", fom, executor="dask").reduce(4)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=True, dashboard_address=None) as cl, \
            distributed.Client(cl):
        res = ms.reducers.make("irka", fom, executor="dask").reduce(4)
    assert res.info["executor"] == "dask" and res.info["lu_count"] == ref.info["lu_count"]
    # the executor only moves the jobs (solver_threads 1 and 2 give the same bits, above): measured 0
    assert _tf_rel_diff(res.rom, ref.rom, np.logspace(-2, 0, 40)) < 1e-12


# -- library backends: KLU (nbklu) and rslab (default dependencies), MKL PARDISO (extra) ---------------
EXTRAS = ("klu", "rslab", "pardiso")


def _need(backend):
    from morsuite.linalg.backends_ext import INSTALL, available
    if not available()[backend]:
        pytest.skip(f"library backend {backend} not installed ({INSTALL[backend]})")


@pytest.mark.parametrize("backend", EXTRAS)
@pytest.mark.parametrize("which", ["dsms", "tcom", "random", "grid3d", "fem"])
def test_library_backends_agree_with_dense_solves(backend, which, dsms50, tcom20, small_random):
    """KLU, rslab and PARDISO: solve and transposed solve against dense ones, real and complex shifts,
    two factorizations alive at once (KLU's pooled solvers and rslab share the pattern's analysis,
    PARDISO one handle each; PARDISO complex symmetric for the symmetric models, unsymmetric for the
    random one)."""
    _need(backend)
    fom = ms.models.fem_block(300) if which == "fem" else \
        {"dsms": dsms50, "tcom": tcom20, "random": small_random, "grid3d": grid3d_model(5)}[which]
    rng = np.random.default_rng(0)
    N = fom.n1 + fom.n2
    B = rng.standard_normal((N, 2)) + 1j * rng.standard_normal((N, 2))
    solver = fom.new_solver(backend=backend, cache_size=4)
    assert solver.backend == backend
    other = solver.factor(0.7 + 0.2j)  # alive while the others are made and used
    with blas_threads(1):
        _check_solves(fom, solver, B)
    x = other.solve(B, full=True)
    assert np.linalg.norm(x - np.linalg.solve(_dense(fom, 0.7 + 0.2j), B)) <= 1e-11 * np.linalg.norm(x)
    assert solver.stats.refactorizations == 0
    if backend == "pardiso":
        assert other.lu.mtype == (13 if which == "random" else 6)


def test_auto_rule_with_the_libraries():
    """The rule from the structure and what is installed: KLU for narrow bands with a border
    (the TCOM), PARDISO for wide bands from pardiso_min_n rows, else rslab from rslab_min_n rows,
    SuperLU without the libraries."""
    none = {"klu": False, "rslab": False, "pardiso": False}
    default = {"klu": True, "rslab": True, "pardiso": False}
    every = {"klu": True, "rslab": True, "pardiso": True}
    assert choose(2, 2, 6, 200000, none)[0] == "banded"
    assert choose(2, 2, 6, 200000, default)[0] == "klu"
    assert choose(2, 2, 6, BAND_RULE["klu_min_n"] - 1, default)[0] == "banded"   # tiny: the long-standing rule
    assert choose(1, 1, 1, 200000, every)[0] == "banded"
    assert choose(1, 1, BAND_RULE["max_border"] + 1, 10 ** 5, none)[0] == "superlu"
    assert choose(900, 900, 600, 10 ** 4, every)[0] == "pardiso"
    assert choose(900, 900, 600, 10 ** 4, default)[0] == "rslab"
    assert choose(900, 900, 600, 10 ** 4, none)[0] == "superlu"
    assert choose(900, 900, 600, BAND_RULE["pardiso_min_n"] - 1, every)[0] == "rslab"
    assert choose(90, 90, 60, BAND_RULE["rslab_min_n"] - 1, every)[0] == "superlu"


def test_a_missing_library_is_reported_and_auto_does_without_it(dsms50, monkeypatch):
    """A library that does not import: available() says so, forcing it names its install,
    "auto" chooses among the rest (the FEM block: SuperLU without rslab)."""
    from morsuite.linalg import backends_ext
    monkeypatch.setattr(backends_ext, "_rslab", lambda: None)
    monkeypatch.setattr(backends_ext, "_nbklu", lambda: None)
    monkeypatch.setattr(backends_ext, "_mkl_lib", lambda: None)
    assert backends_ext.available() == {"klu": False, "rslab": False, "pardiso": False}
    for name in EXTRAS:
        with pytest.raises(ms.MorsuiteError, match=name):
            dsms50.lu_backend = name
    assert ms.models.tcom(nc=20).lu_analysis()["backend"] == "banded"  # auto without KLU
    a = ms.models.fem_block(1500).lu_analysis()
    assert a["backend"] == "superlu" and a["available"]["rslab"] is False and "SuperLU" in a["reason"]


def test_auto_does_without_rslab_when_its_analysis_fails(monkeypatch):
    """rslab installed but failing to analyse a pattern: "auto" records why and takes SuperLU,
    forcing rslab raises an InputError."""
    from morsuite.linalg import backends_rslab
    _need("rslab")

    def fails(pattern):
        raise RuntimeError("analysis failed")
    monkeypatch.setattr(backends_rslab, "rslab_symbolic", fails)
    fom = ms.models.fem_block(1500)
    a = fom.lu_analysis()
    assert a["backend"] == "superlu" and "analysis failed" in a["reason"]
    with pytest.raises(ms.MorsuiteError, match="rslab"):
        fom.new_solver(backend="rslab")


def test_auto_choice_on_3d_patterns_is_deterministic_and_recorded():
    """fem_block(1500) (n = 1728 >= rslab_min_n): rslab where installed, the same analysis from two
    fresh models (plain data, the analysis' predicted fill recorded), and in a reducer's info."""
    from morsuite.linalg.backends_ext import available
    a, b = ms.models.fem_block(1500).lu_analysis(), ms.models.fem_block(1500).lu_analysis()
    assert a == b and a["kl"] + a["ku"] > BAND_RULE["max_band"]
    if available()["rslab"] and not available()["pardiso"]:
        assert a["backend"] == "rslab" and "rslab" in a["reason"] and a["predicted_factor_nnz"] > a["nnz"]


@pytest.mark.parametrize("backend, kind, s", [("klu", "KLULU", 0.4 + 1.3j), ("rslab", "RslabLU", 0.4 + 1.3j),
                                               ("rslab", "RslabLU", 0.4), ("rslab", "RslabLDLT", 0.4 + 1.3j)])
def test_a_tampered_factor_falls_back_to_superlu(backend, kind, s, tcom20, monkeypatch):
    """A library's factorization whose solves are wrong (tampered) fails the backward-error check:
    the solver refactors (SuperLU; rslab's LU for its LDL^T, counted), and the solution is the dense one."""
    from morsuite.linalg import backends_ext, backends_rslab
    _need(backend)
    cls = getattr(backends_rslab if kind.startswith("Rslab") else backends_ext, kind)
    if kind == "RslabLU":  # the TCOM is symmetric: rslab's LU only where its LDL^T does not apply
        monkeypatch.setattr(backends_rslab, "rslab_ldlt_symbolic", lambda pattern: None)
    honest = cls.solve
    monkeypatch.setattr(cls, "solve", lambda self, b, trans="N": 1.001 * honest(self, b, trans))
    solver = tcom20.new_solver(backend=backend)
    f = solver.factor(s)
    assert isinstance(f.lu, cls)
    for trans in (False, True):
        x = f.solve(tcom20.F, trans=trans, full=True)
        S = _dense(tcom20, s)
        ref = np.linalg.solve(S.T if trans else S, np.vstack([tcom20.F, np.zeros((tcom20.n2, 1))]))
        # measured <= 1e-15, bounds >= 2e-11
        assert_rounding(np.linalg.norm(x - ref) / np.linalg.norm(ref), solve_tolerance(S), "after refactoring")
    assert solver.stats.refactorizations == 1 and not isinstance(f.lu, cls)


@pytest.mark.parametrize("backend", ["klu", "rslab"])
def test_a_pole_raises_singular_shift_error(backend):
    """An exactly singular saddle matrix (s = 0 of a mass-only model: A11 = s^2 M = 0, rank 2 n2):
    the library reports it, SuperLU confirms, SingularShiftError (no crash, no silent answer)."""
    _need(backend)
    n1 = 40
    Z = sp.csr_matrix((n1, n1))
    G = sp.csr_matrix((np.array([1.0, -1.0]), (np.array([0, 0]), np.array([3, 7]))), shape=(1, n1))
    rng = np.random.default_rng(3)
    fom = ms.models.Index3Model(sp.identity(n1, format="csr"), Z, Z, G, rng.standard_normal((n1, 1)),
                                rng.standard_normal((1, n1)), name="masses", check_constraints=False)
    solver = fom.new_solver(backend=backend)
    with pytest.raises(ms.errors.SingularShiftError):
        solver.factor(0.0).solve(fom.F)
    S = _dense(fom, 0.5j)
    b = np.vstack([fom.F, np.zeros((1, 1))])
    x = solver.factor(0.5j).solve(b, full=True)  # away from the pole: the dense solution
    # measured 0, bound 9e-14
    assert_rounding(np.linalg.norm(x - np.linalg.solve(S, b)) / np.linalg.norm(x), solve_tolerance(S), "solve")


def test_klu_refactor_with_too_much_growth_factors_afresh(tcom20, monkeypatch):
    """KLU refactors with the pattern's reference pivot order; where the pivot growth check fails
    (forced here: no growth accepted) the matrix is factored afresh with its own pivoting, the
    same solution, no SuperLU fallback; a refactorization that passes is the default."""
    from morsuite.linalg import backends_ext
    _need("klu")
    s = 0.4 + 1.3j
    b = np.vstack([tcom20.F, np.zeros((tcom20.n2, 1))])
    ref = np.linalg.solve(_dense(tcom20, s), b)
    plain = tcom20.new_solver(backend="klu").factor(s)
    assert plain.lu.refactored and plain.lu.rgrowth >= backends_ext.KLU_MIN_RGROWTH
    monkeypatch.setattr(backends_ext, "KLU_MIN_RGROWTH", 2.0)  # rgrowth <= 1 always
    solver = tcom20.new_solver(backend="klu")
    f = solver.factor(s)
    assert not f.lu.refactored
    assert np.linalg.norm(f.solve(b, full=True) - ref) <= 1e-11 * np.linalg.norm(ref)
    assert solver.stats.refactorizations == 0


@pytest.mark.parametrize("backend", ["klu", "rslab"])
def test_fem_transfer_of_the_library_backends_agrees_with_superlu(backend):
    """The FEM block's transfer function at a few shifts in its band by KLU and rslab against
    SuperLU's: 1e-8 relative (their backward errors are ~1e-16; the block's conditioning is mild)."""
    _need(backend)
    vals = {}
    for b in ("superlu", backend):
        fom = ms.models.fem_block(600)
        fom.lu_backend = b
        w = np.geomspace(fom.band[0], fom.band[1], 4)
        vals[b] = np.array([fom.transfer(1j * x) for x in w])
    assert np.max(np.abs(vals[backend] - vals["superlu"])) <= 1e-8 * np.max(np.abs(vals["superlu"]))


@pytest.mark.parametrize("backend", EXTRAS)
def test_library_backends_roms_agree_and_are_deterministic(backend):
    """Converged IRKA ROMs with KLU or PARDISO against SuperLU's: transfer functions to 1e-8;
    and the same ROM, bit for bit, from a fresh model and after other runs on it, on 1 or 2 solver threads."""
    _need(backend)
    omega = np.logspace(-2, 1, 60)
    roms = {}
    for b in ("superlu", backend):
        fom = ms.models.tcom(nc=200)
        fom.lu_backend = b
        res = ms.reducers.make("irka", fom).reduce(6)
        assert res.info["converged"] and res.info["lu_backend"]["backend"] == b
        roms[b] = res
    assert _tf_rel_diff(roms[backend].rom, roms["superlu"].rom, omega) < 1e-8
    again = ms.reducers.make("irka", _after_other_runs(backend), solver_threads=2).reduce(6)
    assert again.info["iterations"] == roms[backend].info["iterations"]
    for k in ("M", "D", "K", "F", "L"):
        assert np.array_equal(getattr(again.rom, k), getattr(roms[backend].rom, k)), k


@pytest.mark.parametrize("backend", EXTRAS)
def test_library_backends_pickle_without_their_handles(backend, tcom20):
    """A solver goes to Dask workers pickled: its cached library factorizations stay behind
    (process handles), the pattern's analysis is redone there; the copy solves the same.
    KLU holds the GIL (nbklu), so IRKA's automatic solver threads are 1 with it."""
    import pickle

    from morsuite.reducers.irka.shift_solves import default_threads
    _need(backend)
    solver = tcom20.new_solver(backend=backend)
    x = solver.factor(0.3j).solve(tcom20.F)
    copy = pickle.loads(pickle.dumps(solver))
    assert len(copy._cache) == 0
    # measured 0, bound 2e-11 (the same backend and ordering: the last bits may differ with its threads)
    assert_rounding(np.linalg.norm(copy.factor(0.3j).solve(tcom20.F) - x) / np.linalg.norm(x),
                    solve_tolerance(_dense(tcom20, 0.3j)), "pickled copy")
    assert default_threads("klu") == 1


def test_rslab_takes_its_ldlt_at_complex_symmetric_shifts():
    """fem_block (M, D, K symmetric): at complex shifts rslab factors S(s) by its LDL^T (perturbed
    pivots, refined solves), at a real one by its LU; the solves, plain and transposed, equal the
    dense ones. With an unsymmetric D a complex shift gets the LU."""
    from morsuite.linalg.backends_rslab import RslabLDLT, RslabLU
    _need("rslab")
    fom = ms.models.fem_block(300)
    B = np.vstack([np.asarray(fom.F.todense() if sp.issparse(fom.F) else fom.F), np.zeros((fom.n2, fom.m))])
    solver = fom.new_solver(backend="rslab")
    for s, cls in ((0.7j, RslabLDLT), (0.05 + 2.0j, RslabLDLT), (0.7, RslabLU)):
        f = solver.factor(s)
        assert type(f.lu) is cls and solver.stats.refactorizations == 0
        S = _dense(fom, s)
        for trans in (False, True):
            ref = np.linalg.solve(S.T if trans else S, B)
            x = f.solve(B, trans=trans, full=True)
            assert np.linalg.norm(x - ref) <= 1e-10 * np.linalg.norm(ref)
    D = fom.D.tolil()
    D[0, 1] += 1e-3 * abs(D[0, 0]) + 1e-3  # unsymmetric damping: S(s) is not complex symmetric
    other = ms.models.Index3Model(fom.M, D.tocsr(), fom.K, fom.G, fom.F, fom.L, name="fem unsym",
                                  check_constraints=False)
    unsym = other.new_solver(backend="rslab")
    f = unsym.factor(0.7j)
    assert type(f.lu) is RslabLU
    assert unsym.pattern[("rslab-ldlt",)].value is None  # "not symmetric" is kept: not checked again per shift
    S = _dense(other, 0.7j)
    ref = np.linalg.solve(S, B)
    assert np.linalg.norm(f.solve(B, full=True) - ref) <= 1e-10 * np.linalg.norm(ref)
