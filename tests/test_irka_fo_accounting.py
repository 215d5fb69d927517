"""irka-fo's cost accounting across reducers and orders (issue 27, item 3): the Gramian factors shared
with bt through the model's cache, and the surrogate's BT projection cached with headroom."""

from __future__ import annotations

import warnings

import morsuite as ms
from morsuite.reducers.outcome import standalone_lu_count, standalone_time


def _reduce(red, r):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return red.reduce(r).info


def test_factors_computed_by_bt_are_reported_as_shared_by_a_fresh_irka_fo():
    fom = ms.models.parse("tcom:nc=20")
    bt = _reduce(ms.reducers.make("bt", fom), 4)
    assert bt["lu_count"] == bt["lu_count_shared"] > 0  # bt paid the LR-ADI
    info = _reduce(ms.reducers.make("irka-fo", fom), 6)
    # a fresh irka-fo reducer reuses the model's factors: it pays none of their LUs, and says how many they were
    assert info["lu_count_start"] == 0 and info["lu_count"] == info["lu_count_own"]
    assert info["lu_count_shared"] == bt["lu_count_shared"]
    assert standalone_lu_count(info) == info["lu_count_own"] + bt["lu_count_shared"]


def test_surrogate_projection_is_built_once_and_added_back_for_standalone_times():
    fom = ms.models.parse("tcom:nc=20")
    red = ms.reducers.make("irka-fo", fom)
    first = _reduce(red, 8)
    paid = first["time_breakdown"]["surrogate_projection"]
    assert paid > 0 and first["setup_cost"]["surrogate_projection"] == paid
    R = red._bt._gram["projected"]["first-order"]["R"]
    assert R >= first["surrogate"]["states"]
    second = _reduce(red, 6)  # a smaller surrogate: the cached projection serves it
    assert second["surrogate"]["states"] <= R
    assert second["time_breakdown"]["surrogate_projection"] == 0.0
    assert red._bt._gram["projected"]["first-order"]["R"] == R
    assert second["setup_cost"]["surrogate_projection"] == paid
    assert standalone_time(second) >= second["time_s"] + paid
