"""Free-floating models (morsuite.models.rigid): detection, deflation, the rigid part added back.

References are independent of the deflation: a dense null-space basis of G (eigenvalues of
K on ker G, the model's poles), and contour integrals of the full model's own T(s) (sparse
LUs of the original saddle matrix) around the rigid poles.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.errors import InputError, ModelError
from morsuite.models.rigid import flexible_part, rigid_block, rigid_body_modes, split
from support import assert_rounding, orthonormality_error, rounding_unit

METHODS = {"modal": {}, "krylov": {}, "irka": {}, "irka-projected": {}, "irka-fo": {}, "bt": {},
           "bt-fl": {"nodes": 24}, "so-h2": {"maxit": 100}}


def _free_chain():
    return ms.models.dsms(g=40, free=True)


def _free_block():
    return ms.models.fem_block(n1=120, clamp="none")


def _dense(model):
    """Null-space basis Z of G and the model's matrices on it (dense)."""
    Z = sla.null_space(model.G.toarray()) if model.n2 else np.eye(model.n1)
    return Z, *(Z.T @ (X @ Z) for X in (model.M, model.D, model.K))


def _radius(model, k):
    """Half the modulus of the smallest pole beyond the 2k rigid ones (dense quadratic eigenproblem)."""
    Z, M, D, K = _dense(model)
    n = M.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-K, -D]])
    E = sla.block_diag(np.eye(n), M)
    lam = sla.eigvals(A, E)
    lam = lam[np.isfinite(lam)]
    # the 2k rigid poles: 0 and -eig(D_rigid) (lambda^2 + lambda D_r = 0); the others matched away from them
    # by distance (a cut, not a sorted position)
    Dr = rigid_block(model)[1]
    rigid = np.concatenate([np.zeros(k), -np.linalg.eigvals(Dr)])
    scale = np.abs(lam).max()
    far = np.array([np.min(np.abs(rigid - x)) > 1e-8 * scale for x in lam])
    assert lam.size - far.sum() == 2 * k
    return 0.5 * np.abs(lam[far]).min()


def _rigid_moments(transfer, rho, N=64):
    r"""(1/2 pi i) \oint s^j T(s) ds, j = 1, 2, on |s| = rho (trapezoidal rule, exponentially accurate):
    L Phi Phi^T F and -L Phi D_Phi Phi^T F, the coefficients of 1/s^2 and 1/s^3 of the rigid part."""
    s = rho * np.exp(2j * np.pi * (np.arange(N) + 0.5) / N)
    T = np.array([transfer(si) for si in s])
    return [np.real(np.mean(T * (s ** (j + 1))[:, None, None], axis=0)) for j in (1, 2)]


@pytest.fixture(scope="module")
def chain():
    return _free_chain()


@pytest.fixture(scope="module")
def block():
    return _free_block()


def test_detection_matches_the_dense_null_space(chain, block):
    for model, k in ((chain, 1), (block, 6)):
        rigid = rigid_body_modes(model)
        assert rigid.k == k and rigid.info["method"] == "lanczos" and rigid.info["lu_count"] == 1
        Z, M, _, K = _dense(model)
        lam, V = sla.eigh(K, M)
        scale = np.max(np.abs(lam))
        assert np.sum(np.abs(lam) <= 1e-10 * scale) == k  # the dense count agrees
        null = Z @ V[:, :k]
        # the same subspace: principal angles zero to rounding
        angles = sla.subspace_angles(null, rigid.shapes)
        assert np.max(angles) < 1e-8
        Phi = rigid.shapes
        err, tol = orthonormality_error(Phi, model.M)
        assert err <= tol, (err, tol)
        if model.n2:  # the solves' constraint rows (as for the ADI factors): measured 0, bound 10 rounding_unit(N)
            assert_rounding(np.linalg.norm(model.G @ Phi) / (abs(model.G).sum(axis=1).max() * np.linalg.norm(Phi)),
                            10 * rounding_unit(model.n1 + model.n2), "G Phi")
        assert np.isclose(rigid.lowest_flexible, np.sqrt(lam[k]), rtol=1e-8)
        assert rigid_body_modes(model) is rigid  # cached
        assert f"{k} rigid-body mode" in rigid.line(model.name)


def test_no_rigid_modes_on_grounded_and_clamped_models():
    dsms = ms.models.dsms(g=40)
    assert rigid_body_modes(dsms).k == 0 and rigid_body_modes(dsms).info["lu_count"] == 0  # diagonal dominance
    clamped = ms.models.fem_block(n1=192)
    assert rigid_body_modes(clamped).k == 0 and rigid_body_modes(clamped).info["method"] == "lanczos"
    assert flexible_part(dsms) is dsms


def test_flexible_part_is_T_minus_its_rigid_part(chain, block):
    for model in (chain, block):
        rigid = rigid_body_modes(model)
        flex = flexible_part(model)
        assert flex.n2 == model.n2 + rigid.k and rigid_body_modes(flex).k == 0
        Z, M, D, K = _dense(model)
        s = 0.3 + 0.7j
        Tref = model.L @ Z @ np.linalg.solve(s * s * M + s * D + K, Z.T @ model.F)
        Phi = rigid.shapes
        Trig = model.L @ Phi @ np.linalg.solve(s * s * np.eye(rigid.k) + s * rigid.damping, Phi.T @ model.F)
        assert np.linalg.norm(flex.transfer(s) + Trig - Tref) <= 1e-10 * np.linalg.norm(Tref)


@pytest.mark.parametrize("name", ["chain", "block"])
@pytest.mark.parametrize("method", list(METHODS))
def test_every_method_keeps_the_rigid_part_exactly(name, method, request):
    model = request.getfixturevalue(name)
    k = rigid_body_modes(model).k
    r = 4
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = ms.reducers.make(method, model, **METHODS[method]).reduce(r)
    rom = res.rom
    assert res.info["rigid_modes"]["count"] == k and rom.rigid_order == k
    assert rom.flexible.is_stable() and res.info["stable"]
    assert rom.states == rom.flexible.states + 2 * k
    rho = _radius(model, k)
    full = _rigid_moments(model.transfer, rho)
    red = _rigid_moments(rom.transfer, rho)
    scale = np.linalg.norm(full[0]) + rho * np.linalg.norm(full[1])
    for a, b in zip(red, full):
        assert np.linalg.norm(a - b) <= 1e-10 * scale, (method, name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        e, d = ms.analysis.h2_error(model, rom, details=True)
    assert np.isfinite(e) and d["trusted"] and d["part"] == "flexible" and d["rigid_modes"] == k
    # the same number as the flexible parts' error, and an independent sample of it
    w = 0.5 * rho
    ref = model.transfer(1j * w) - rom.transfer(1j * w)
    flex = flexible_part(model).transfer(1j * w) - rom.flexible.transfer(1j * w)
    assert np.linalg.norm(ref - flex) <= 1e-8 * (np.linalg.norm(model.transfer(1j * w)))
    # the lift (positions x = V q: the rigid shapes, then the flexible part's lift) stays on the hidden
    # manifold and reproduces the output map, for second- and first-order reduced models alike
    V = rom.basis
    if method != "so-h2":
        C = rom.L if isinstance(rom, ms.rom.SecondOrderROM) else rom.C
        G = model.G.toarray()
        assert V is not None and V.shape == (model.n1, C.shape[1])
        assert np.linalg.norm(G @ V) <= 1e-10 * np.linalg.norm(G) * np.linalg.norm(V)
        assert np.linalg.norm(model.L @ V - C) <= 1e-10 * np.linalg.norm(np.asarray(model.L)) * np.linalg.norm(V)


def test_norms_refuse_or_route(chain, tmp_path):
    with pytest.raises(InputError, match="rigid-body modes"):
        ms.analysis.h2_norm(chain)
    rom = ms.reducers.make("bt", chain).reduce(4).rom
    # a reduced model without the rigid part: T - T_r has a pole at 0
    with pytest.warns(Warning, match="rigid-body modes"):
        assert ms.analysis.h2_error(chain, rom.flexible) == np.inf
    # read back from a file, the rigid block is found again from its exact structure
    path = rom.save(tmp_path / "rom.npz")
    back = ms.rom.load_rom(path)
    assert not hasattr(back, "flexible")
    fm, fr, k = split(chain, back)
    assert k == 1 and fm is flexible_part(chain)
    assert ms.analysis.h2_error(chain, back) == pytest.approx(ms.analysis.h2_error(chain, rom), rel=1e-12)
    # the Hinf search's start grid takes the flexible part's Gramian factors: compare prepares those, never
    # the free model's own (a pole at 0: its LR-ADI cannot converge and ran to maxiter, 18 s here)
    from morsuite.analysis.compare import error_norm
    from morsuite.linalg.gramians import cached_gramian_factors

    fresh = _free_chain()
    rec = error_norm(fresh, rom, "hinf")
    value, d = ms.analysis.hinf_error(chain, rom, details=True)
    # both certified: each lower bound below the other's upper bound (whatever each model's cache held)
    assert rec["certified"] and d["certified"]
    assert rec["value"] <= d["upper_bound"] and value <= rec["upper_bound"]
    assert cached_gramian_factors(flexible_part(fresh)) is not None and cached_gramian_factors(fresh) is None


def test_coupled_damping_is_refused():
    model = ms.models.dsms(g=40, kappa=0, kappa_end=0)  # end dampers 10, others 5: D 1 not in span(M 1)
    assert rigid_body_modes(model).k == 1 and rigid_body_modes(model).coupling > 1e-8
    with pytest.raises(ModelError, match="couples"):
        ms.reducers.make("bt", model)
    even = ms.models.dsms(g=40, kappa=0, kappa_end=0, delta_end=5.0)  # uniform grounding dampers: D 1 = 0.05 M 1
    # no coupling: the rounding of its solve and sums over n1 terms (measured 3e-17, bound 1.4e-13)
    assert_rounding(rigid_body_modes(even).coupling, 10 * rounding_unit(even.n1), "coupling")
    assert np.allclose(rigid_body_modes(even).damping, 0.05 * np.eye(1))


def test_model_options_are_validated():
    with pytest.raises(InputError, match="clamp"):
        ms.models.fem_block(n1=192, clamp="y0")
    with pytest.raises(InputError, match="free"):
        ms.models.dsms(g=40, free="yes")
    assert ms.models.parse("fem_block:n1=192,clamp=none").n2 == 0
    assert ms.models.parse("dsms:g=40,free=true").K.sum() == pytest.approx(0.0, abs=1e-12)


def test_cli_compare_on_a_free_free_chain(tmp_path, capsys):
    from morsuite.cli import main

    rc = main(["compare", "dsms:g=40,free=true", "--states", "8", "--methods", "bt", "--out",
               str(tmp_path), "--quiet"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "1 rigid-body mode" in out
    table = out.split("== ")[1]
    assert " inf " not in table and "bt " in table
    assert main(["info", "dsms:g=40,free=true"]) == 0
    captured = capsys.readouterr()
    assert "1 rigid-body mode" in captured.err and '"count": 1' in captured.out


def test_cli_reduce_json_on_a_free_free_chain(capsys):
    import json

    from morsuite.cli import main

    assert main(["reduce", "--model", "dsms:g=40,free=true", "--method", "bt", "--r", "4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["rigid_modes"] == 1 and out["states"] == 6 and np.isfinite(out["h2_error"]) and out["stable"]


def test_damped_means_beyond_rounding(chain, block):
    """dsms's D = 2.5 K annihilates its rigid mode exactly (K Phi in range G^T, G Phi = 0): D_Phi is rounding
    (measured 4e-33), not damping; fem_block's Rayleigh D = alpha M + beta K gives D_Phi = alpha I exactly."""
    free = rigid_body_modes(chain)
    assert not free.damped and not free.summary()["damped"]
    assert_rounding(np.abs(free.damping).max(), free.info["damping_tol"], "D_Phi of D = 2.5 K")
    body = rigid_body_modes(block)
    assert body.damped and body.summary()["damped"]
    alpha = 1e-3  # fem_block's default Rayleigh coefficient of M
    assert_rounding(np.abs(body.damping - alpha * np.eye(body.k)).max(), body.info["damping_tol"] + 1e-8 * alpha,
                    "D_Phi - alpha I")


def test_a_failed_or_partial_detection_is_said_and_never_converged(monkeypatch):
    """The detection raising (planted: the shift is an eigenvalue, as for an indefinite K) or ARPACK converging
    4 of 8 modes (planted): the detection's status and reason, a warning, and every reducer's info with status
    'detection-failed'."""
    import scipy.sparse.linalg as spla

    from morsuite.errors import ConvergenceWarning, SingularShiftError
    from morsuite.linalg import eigen

    def broken(*args, **kwargs):
        raise SingularShiftError("planted: the shift is an eigenvalue")

    real = spla.eigsh

    def partial(*args, **kwargs):
        lam, X = real(*args, **kwargs)
        raise spla.ArpackNoConvergence("planted", lam[:4], X[:, :4])

    for where, fake, status, why in ((eigen, broken, "failed", "shift is an eigenvalue"),
                                     (eigen.spla, partial, "partial", "converged 4 of 8")):
        model = ms.models.fem_block(n1=192)  # clamped: no rigid mode, K not diagonally dominant (Lanczos runs)
        with monkeypatch.context() as mp:
            mp.setattr(where, "constrained_modes" if where is eigen else "eigsh", fake)
            with pytest.warns(ConvergenceWarning, match=why):
                rigid = rigid_body_modes(model)
        assert rigid.k == 0 and rigid.info["status"] == status and why in rigid.info["reason"]
        assert status in rigid.line(model.name)
        with pytest.warns(ConvergenceWarning, match="rigid-body detection"):
            res = ms.reducers.make("krylov", model).reduce(4)
        info = res.info
        assert info["status"] == "detection-failed" and info["converged"] is False
        assert info["method_status"] == "direct" and why in info["status_reason"]
        assert info["rigid_modes"]["status"] == status and info["rigid_modes"]["count"] == 0
        assert any("rigid-body detection" in w for w in info["warnings"])
