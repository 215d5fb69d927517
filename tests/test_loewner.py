"""`loewner`: data-driven reduction from samples of T(jw), checked against independent references.

- The full-rank Loewner model of a few samples interpolates every sample (left and right points,
  every input-output pair), to the rounding of a dense solve with its pencil, against the model's
  own transfer function.
- Sampled densely, a model of McMillan degree 20 is identified: the pencil's numerical rank is 20 and
  the model of order 20 matches a dense computation of T (numpy's solve with the saddle matrix) at
  1000 frequencies between the samples to the rounding the pencil's smallest kept singular value
  allows.
- The samples come from the model's memo of T(jw): after a band response on the same grid the
  reduction pays no LU and returns the same model, bit for bit, as on a fresh model (200 LUs).
- Bad options are refused with messages naming them; r above the pencil's rank is capped with a warning.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import morsuite as ms
from morsuite.errors import InputError, OptionError, RankWarning
from morsuite.reducers.outcome import standalone_lu_count, standalone_time
from support import assert_rounding, rounding_unit, transfer_tolerance


def _dense_transfer(fom, omega):
    """T(jw) from numpy's dense solve with the saddle matrix [[s^2 M + s D + K, G^T], [G, 0]]."""
    M, D, K, G = (X.toarray() for X in (fom.M, fom.D, fom.K, fom.G))
    n1, n2 = fom.n1, fom.n2
    out = []
    for w in omega:
        s = 1j * w
        S = np.block([[s * s * M + s * D + K, G.T], [G, np.zeros((n2, n2))]])
        X = np.linalg.solve(S, np.vstack([fom.F, np.zeros((n2, fom.m))]))
        out.append(fom.L @ X[:n1])
    return np.array(out)


def test_full_rank_model_interpolates_every_sample():
    fom = ms.models.random_constrained(n1=40, n2=3, m=2, p=2, seed=1)
    omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), 10)
    red = ms.reducers.make("loewner", fom, omega=omega)
    r = red.max_order()
    assert r == 20  # 5 left and 5 right frequencies, each with its conjugate, 2 outputs / 2 inputs each
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # an interpolant of 10 samples need not be stable
        res = red.reduce(r)
    rom = res.rom
    assert rom.order == r and res.info["rank"] == r and res.info["imag_dropped"] <= rounding_unit(r)
    assert all(np.isrealobj(X) for X in (rom.E, rom.A, rom.B, rom.C))
    H = _dense_transfer(fom, omega)
    for w, Hk in zip(omega, H):
        for s, ref in ((1j * w, Hk), (-1j * w, np.conj(Hk))):  # the point and its conjugate
            P = s * rom.E - rom.A
            err = np.linalg.norm(rom.transfer(s) - ref) / np.linalg.norm(ref)
            # the dense solve with the pencil, whose condition sets the bound (measured 3e-16 to 4e-13 against
            # bounds 4e-4 to 40: a Loewner realization is ill-conditioned at its own points)
            assert_rounding(err, transfer_tolerance(P, rom.B, rom.C, factor=2) + rounding_unit(fom.n1),
                            f"interpolation at {s:.3g}")


def test_identifies_a_model_of_low_degree_on_the_band():
    fom = ms.models.random_constrained(n1=12, n2=2, m=1, p=1, seed=3)
    degree = 2 * fom.order  # 20 first-order states: its McMillan degree
    res = ms.reducers.make("loewner", fom, samples=200).reduce(degree)
    sv = np.asarray(res.info["singular_values"])
    assert res.info["rank"] == degree and res.info["status"] == "direct"
    assert sv[degree] <= 1e-12 < sv[degree - 1]  # the gap that sets the rank (measured 1.1e-15 after 1.4e-8)
    omega = np.logspace(np.log10(fom.band[0]), np.log10(fom.band[1]), 1000)  # between the samples
    H, Hr = _dense_transfer(fom, omega), res.rom.freqresp(omega)
    err = np.max(np.abs(Hr - H)) / np.max(np.abs(H))
    # a perturbation of the data and pencil at rounding level, amplified by the smallest kept singular
    # value (measured 1.2e-14 against the bound 1.1e-6)
    assert_rounding(err, rounding_unit(sv.size) / sv[degree - 1], "band error of the identified model")
    assert res.info["lu_count"] == 200 == res.info["lu_count_shared"]


def test_band_response_memo_serves_the_samples():
    fom = ms.models.dsms(g=40)
    omega = ms.analysis.freq_grid(fom.band, 200)
    _, lus = ms.analysis.band_response(fom, omega)
    assert lus == 200
    shared = ms.reducers.make("loewner", fom).reduce(8)
    fresh = ms.reducers.make("loewner", ms.models.dsms(g=40)).reduce(8)
    assert shared.info["lu_count"] == 0 and shared.info["samples_from_memo"] == 200
    assert fresh.info["lu_count"] == 200 and fresh.info["samples_from_memo"] == 0
    assert standalone_lu_count(shared.info) == standalone_lu_count(fresh.info) == 200
    # the samples' time, paid by the band response, is still counted: the memo keeps each one's seconds
    kept = fom.cache[("fom_response_seconds", 1)]
    assert shared.info["setup_cost_unknown"] == []
    assert shared.info["setup_cost"]["samples"] == pytest.approx(sum(kept[complex(1j * w)] for w in omega), rel=1e-12)
    paid = shared.info["setup_paid"]["samples"]  # reading them from the memo
    assert standalone_time(shared.info) >= shared.info["time_s"] + shared.info["setup_cost"]["samples"] - paid
    for a, b in zip((shared.rom.E, shared.rom.A, shared.rom.B, shared.rom.C),
                    (fresh.rom.E, fresh.rom.A, fresh.rom.B, fresh.rom.C)):
        assert np.array_equal(a, b)  # the same samples (the memo keeps what a fresh solve computes)
    again = ms.reducers.make("loewner", fom)
    again.reduce(4)
    assert again.reduce(8).info["lu_count"] == 0  # every r from one set of samples and SVDs


def test_rank_cap_and_refusals():
    fom = ms.models.random_constrained(n1=12, n2=2, m=1, p=1, seed=3)
    red = ms.reducers.make("loewner", fom, samples=60, rank_tol=1e-4)
    with pytest.warns(RankWarning, match="r capped from 16 to"):
        res = red.reduce(16)
    assert res.info["rank_capped"] and res.rom.order == res.info["rank"] < 16
    with pytest.raises(OptionError, match=r"The 'samples' parameter of Loewner must be an int in \[2, inf\)"):
        ms.reducers.make("loewner", fom, samples=1)
    with pytest.raises(InputError, match="The 'omega' parameter of Loewner must hold at least 2 distinct"):
        ms.reducers.make("loewner", fom, omega=[1.0, 1.0])
    with pytest.raises(InputError, match="The 'band' parameter of Loewner must satisfy 0 < lo < hi"):
        ms.reducers.make("loewner", fom, band=[2.0, 1.0])
    with pytest.raises(InputError, match="r = 21 exceeds"):
        ms.reducers.make("loewner", fom).reduce(21)
