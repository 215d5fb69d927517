"""irka-fo's certification round (issue 27, item 2, 2026-11-26 third session): its solves make no basis,
so they are not refined (``refine_certificate=False``). Checked: the returned model is the same to the
bit, the certificate the same to the LU's forward error, and it still matches the dense interpolation
residual of the projected model (an independent reference)."""

from __future__ import annotations

import warnings

import numpy as np

import morsuite as ms
from morsuite.reducers.irka import second_order as irka_module

from test_irka_fo import Projected, hermite_mismatch, modal

SPEC = "dsms:g=100"  # at 20 states the bases are ill-conditioned from the first iteration on: the later ones refine


def _run(monkeypatch, **options):
    calls = {"n": 0}
    real = irka_module.refined_solve

    def counting(*args, **kwargs):
        calls["n"] += 1
        return real(*args, **kwargs)
    monkeypatch.setattr(irka_module, "refined_solve", counting)
    fom = ms.models.parse(SPEC)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = ms.reducers.make("irka-fo", fom, solver_threads=1, **options).reduce(20)
    return fom, res, calls["n"]


def test_certification_round_is_unrefined_and_changes_nothing_else(monkeypatch):
    fom, ref, n_ref = _run(monkeypatch, refine_certificate=True)
    _, res, n = _run(monkeypatch)
    info = res.info
    assert info["options"]["refine_certificate"] is False and info["converged"] and ref.info["converged"]
    assert info["history"]["refined"][-1]  # the last iteration refined: the certification round would have
    cert_lus = info["certificate"]["lu_count"]
    assert cert_lus > 0 and info["lu_count_own"] == ref.info["lu_count_own"]
    # two refined solves per LU of the certification round are gone, nothing else
    assert n_ref - n == 2 * cert_lus
    for name in ("E", "A", "B", "C"):  # the same model, bit for bit: the round makes no basis
        assert np.array_equal(getattr(res.rom, name), getattr(ref.rom, name))
    # the certificate from unrefined solves: at the rounding level, as the refined one
    c, c_ref = info["certificate"]["residual"], ref.info["certificate"]["residual"]
    assert c < 1e-10 and c_ref < 1e-10 and abs(c - c_ref) < 1e-11
    # the independent reference: the dense projected model's Hermite mismatch at the mirrored poles
    lam, bres, cres = modal(res.rom)
    a = -lam
    mism = hermite_mismatch(Projected(fom), res.rom, a, bres, cres.T)
    assert mism <= info["certificate"]["tol"] * np.max(np.abs(a) / a.real)
