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
        f = solver.factor(s)
        for trans in (False, True):
            x = f.solve(B, trans=trans, full=True)
            ref = np.linalg.solve(S.T if trans else S, B)
            assert np.linalg.norm(x - ref) <= 1e-11 * np.linalg.norm(ref), (backend, s, trans)
            assert f.backward_error(B, trans=trans) < 1e-14, (backend, s, trans)
        g = solver.factor(np.conj(s))  # the conjugate view of the same factors
        Sc = _dense(fom, np.conj(s))
        assert np.allclose(g.solve(B, full=True), np.linalg.solve(Sc, B), rtol=1e-11, atol=0)


def test_auto_choice_is_structural_and_recorded(dsms50, tcom20):
    """Chains get the banded LU (the TCOM's border of 6 rows KLU where installed), a small 3D grid
    SuperLU; the analysis is plain data on the model."""
    from morsuite.linalg.backends_ext import available
    for fom, kl_ku, want in ((dsms50, (1, 1), "banded"),
                             (tcom20, (2, 2), "klu" if available()["klu"] else "banded")):
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
    assert _tf_rel_diff(res.rom, ref.rom, np.logspace(-2, 0, 40)) < 1e-12


# -- optional extras: KLU (kvxopt, GPL-3) and MKL PARDISO; skipped where not installed -----------------
EXTRAS = ("klu", "pardiso")


def _need(backend):
    from morsuite.linalg.backends_ext import available
    if not available()[backend]:
        pytest.skip(f"optional backend {backend} not installed (pip install morsuite[{backend}])")


@pytest.mark.parametrize("backend", EXTRAS)
@pytest.mark.parametrize("which", ["dsms", "tcom", "random", "grid3d", "fem"])
def test_optional_backends_agree_with_dense_solves(backend, which, dsms50, tcom20, small_random):
    """KLU and PARDISO: solve and transposed solve against dense ones, real and complex shifts,
    two factorizations alive at once (KLU shares its symbolic analysis, PARDISO one handle each;
    PARDISO complex symmetric for the symmetric models, unsymmetric for the random one)."""
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


def test_auto_rule_with_the_extras():
    """The rule from the structure and what is installed: KLU for narrow bands with a border
    (the TCOM), PARDISO for wide bands from pardiso_min_n rows, SuperLU without the extras."""
    none, both = {"klu": False, "pardiso": False}, {"klu": True, "pardiso": True}
    assert choose(2, 2, 6, 200000, none)[0] == "banded"
    assert choose(2, 2, 6, 200000, both)[0] == "klu"
    assert choose(1, 1, 1, 200000, both)[0] == "banded"
    assert choose(1, 1, BAND_RULE["max_border"] + 1, 10 ** 5, none)[0] == "superlu"
    assert choose(900, 900, 600, 10 ** 4, both)[0] == "pardiso"
    assert choose(900, 900, 600, 10 ** 4, none)[0] == "superlu"
    assert choose(900, 900, 600, BAND_RULE["pardiso_min_n"] - 1, both)[0] == "superlu"


def test_forcing_a_missing_extra_names_it(dsms50, monkeypatch):
    from morsuite.linalg import backends_ext
    monkeypatch.setattr(backends_ext, "available", lambda: {"klu": False, "pardiso": False})
    for name in EXTRAS:
        with pytest.raises(ms.MorsuiteError, match=rf"morsuite\[{name}\]"):
            dsms50.lu_backend = name
    assert ms.models.tcom(nc=20).lu_analysis()["backend"] == "banded"  # auto without the extras


@pytest.mark.parametrize("backend", EXTRAS)
def test_optional_backends_roms_agree_and_are_deterministic(backend):
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
def test_optional_backends_pickle_without_their_handles(backend, tcom20):
    """A solver goes to Dask workers pickled: its cached KLU/PARDISO factorizations stay behind
    (process handles), KLU's symbolic analysis is redone there; the copy solves the same.
    KLU holds the GIL (kvxopt), so IRKA's automatic solver threads are 1 with it."""
    import pickle

    from morsuite.reducers.shift_solves import default_threads
    _need(backend)
    solver = tcom20.new_solver(backend=backend)
    x = solver.factor(0.3j).solve(tcom20.F)
    copy = pickle.loads(pickle.dumps(solver))
    assert len(copy._cache) == 0
    assert np.allclose(copy.factor(0.3j).solve(tcom20.F), x, rtol=1e-12, atol=0)
    assert default_threads("klu") == 1
