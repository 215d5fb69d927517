"""Shared fixtures: test-data paths and small models.

Large models (g = 6000, nc = 2000) are session-scoped so that each is built
once per test run; the small ones are cheap enough to build per test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io as sio
import scipy.sparse as sp

import morsuite as ms
from morsuite.linalg.saddle import SaddlePointSolver

DATA_DIR = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """Directory with the small data files (M.E.S.S. DSMS .mat files)."""
    return DATA_DIR


@pytest.fixture(scope="session", params=[600, 6000], ids=lambda g: f"g{g}")
def mess_file(request):
    """(g, path, raw dict of the .mat file) for both M.E.S.S. DSMS files."""
    g = request.param
    path = DATA_DIR / f"mess_msd_ind3_g{g}.mat"
    return g, path, sio.loadmat(str(path))


@pytest.fixture(scope="session")
def tcom2000():
    return ms.models.tcom(nc=2000)


@pytest.fixture
def dsms50():
    return ms.models.dsms(g=50)


@pytest.fixture
def tcom20():
    return ms.models.tcom(nc=20)


def random_model(n1=12, n2=2, m=2, p=3, seed=0):
    """A small random real model with symmetric positive definite M and K,
    a nonsymmetric D (so that transposed solves differ from plain ones) and a
    full-rank G."""
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n1, n1))
    M = np.eye(n1) + 0.1 * (X @ X.T) / n1
    Y = rng.standard_normal((n1, n1))
    K = Y @ Y.T + n1 * np.eye(n1)
    D = 0.1 * K + 0.05 * rng.standard_normal((n1, n1))
    G = rng.standard_normal((n2, n1))
    F = rng.standard_normal((n1, m))
    L = rng.standard_normal((p, n1))
    return ms.models.Index3Model(sp.csr_matrix(M), sp.csr_matrix(D), sp.csr_matrix(K),
                                 sp.csr_matrix(G), F, L, name="random")


@pytest.fixture
def small_random():
    return random_model()


@pytest.fixture
def make_random_model():
    """Factory ``make_random_model(n1=, n2=, m=, p=, seed=)`` of small random models."""
    return random_model


@pytest.fixture
def valid_parts():
    """Consistent (M, D, K, G, F, L) of a 6-mass chain with one constraint:
    tests of the validation replace one entry at a time."""
    n1 = 6
    M = sp.identity(n1, format="csr") * 2.0
    K = sp.diags([-np.ones(n1 - 1), 3 * np.ones(n1), -np.ones(n1 - 1)], [-1, 0, 1], format="csr")
    D = 0.1 * K
    G = sp.csr_matrix(([1.0, -1.0], ([0, 0], [0, n1 - 1])), shape=(1, n1))
    F = np.zeros((n1, 1))
    F[0, 0] = 1.0
    L = np.zeros((2, n1))
    L[0, 1] = L[1, 2] = 1.0
    return {"M": M, "D": D, "K": K, "G": G, "F": F, "L": L}


@pytest.fixture(scope="session")
def dsms6000_freq():
    """dsms(6000), 200 log-spaced frequencies on its band, and its response (computed once)."""
    fom = ms.models.dsms(6000)
    omega = ms.analysis.freq_grid(fom.band, 200)
    return fom, omega, fom.freqresp(omega)


@pytest.fixture
def count_factorizations(monkeypatch):
    """Counts every sparse LU a SaddlePointSolver makes: each assembles its scaled saddle matrix once
    (``_assemble_scaled``), whatever the solver's cache returns for repeated shifts (a cache hit or the
    conjugate of a factored shift is no LU) and independently of the solver's own counters."""
    from morsuite.linalg.warmup import warm_kernels

    warm_kernels()  # its LUs of a tiny model (the kernels' compilation) are no reduction's: made before counting
    calls = []
    original = SaddlePointSolver._assemble_scaled

    def counted(self, a, b, c, *args, **kwargs):
        calls.append((a, b, c))
        return original(self, a, b, c, *args, **kwargs)

    monkeypatch.setattr(SaddlePointSolver, "_assemble_scaled", counted)
    return calls


# -- random order ---------------------------------------------------------------------------------
def pytest_addoption(parser):
    parser.addoption("--shuffle", type=int, default=None, metavar="SEED",
                     help="run the test modules, and the tests within each, in an order shuffled with SEED "
                          "(the suite must pass in any order; the same SEED gives every xdist worker the same order)")


def pytest_collection_modifyitems(config, items):
    """With ``--shuffle SEED``: modules in a random order, tests within a module too (a module's tests kept
    together so that its module-scoped fixtures are built once), reproducible from SEED."""
    seed = config.getoption("--shuffle")
    if seed is None:
        return
    import random

    rng = random.Random(seed)
    modules: dict = {}
    for item in items:
        modules.setdefault(item.nodeid.split("::", 1)[0], []).append(item)
    groups = list(modules.values())
    rng.shuffle(groups)
    for group in groups:
        rng.shuffle(group)
    items[:] = [item for group in groups for item in group]


def pytest_report_header(config):
    seed = config.getoption("--shuffle")
    return None if seed is None else f"test order shuffled with --shuffle {seed}"
