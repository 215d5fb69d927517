"""Certified H2 errors (issue 25): every floor bounds the error of its value against references
independent of morsuite's solvers, whatever the reduced model's size, pole count or error level.

References (tests/test_norms.py): the error system on the hidden manifold through an explicit
null(G) basis and a dense Lyapunov equation (reliable to about eps ||T||^2 / ||E||^2 relative),
and, for small errors, scipy's adaptive quadrature of ||T(jw) - Tr(jw)||_F^2 with both
responses from dense solves refined in long double (about 1e-12 relative).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

import morsuite as ms
from test_norms import error_ss, extended_h2_error, hidden_ss, lyap_h2

#: relative accuracy of the long-double quadrature reference (its epsrel 1e-13, with margin)
REF_REL = 1e-11


def dense_reference(fom, rom, norm=None):
    """(||T - Tr||_H2 from the dense Lyapunov equation of the error system on the hidden manifold, its
    relative accuracy): it cancels at about eps ||T||^2 / ||E||^2, and Bartels-Stewart's rounding grows
    with ||A|| / sep(A), sep about the smallest damping |Re lambda| (on a random model with a pole of
    damping ratio 6e-4 the dense value was 1.7e-10 off two independent routes of morsuite that agree
    to 1e-15)."""
    norm = lyap_h2(*hidden_ss(fom)) if norm is None else norm
    A, B, C = error_ss(fom, rom)
    dense = lyap_h2(A, B, C)
    lam = np.linalg.eigvals(A)
    eps = np.finfo(float).eps
    acc = 30 * eps * (norm / max(dense, 1e-300)) ** 2 + 10 * eps * A.shape[0] * np.linalg.norm(A, "fro") / np.min(
        np.abs(lam.real))
    return dense, acc


def reference(fom, rom):
    """(||T - Tr||_H2, its relative accuracy): the dense Lyapunov value where it is reliable, else the
    long-double quadrature."""
    dense, acc = dense_reference(fom, rom)
    if acc <= 1e-6:
        return dense, acc
    return extended_h2_error(fom, rom), REF_REL


def _reduce(fom, method, r, **opts):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ms.reducers.make(method, fom, **opts).reduce(r).rom


def _h2(fom, rom, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ms.AccuracyWarning)
        return ms.analysis.h2_error(fom, rom, details=True, **kw)


def test_tcom200_bt_160_states_is_trusted_only_where_it_is_right():
    """The issue's case: first-order BT at 160 states on tcom(nc=200) was reported as 0.00758, trusted,
    rel_floor 2e-5; the dense value is 0.0174 (the quadrature had stopped at its node cap, its estimate
    covering only the pieces it had computed)."""
    fom = ms.models.tcom(nc=200)
    rom = _reduce(fom, "bt", 160)
    assert rom.states == 160 and rom.poles().size == 160
    value, d = _h2(fom, rom)
    assert d["trusted"] and d["consistent"] and d["rel_floor"] <= 1e-6
    # the pole-residue formula, a second route with its own (loose, 3e-2) floor, agrees; the old value
    # 0.00758 is outside it. (The dense Lyapunov reference, 0.0174 to its ~1e-2 here, costs minutes on
    # 1,350 states: measured in docs/design/norms.md, not repeated in the suite.)
    pr, dp = _h2(fom, rom, method="pole-residue")
    assert abs(pr - value) <= dp["floor"] + d["floor"]
    assert abs(pr - 0.00758) > dp["floor"] + 1e-5


def test_error_gramian_route_needs_no_lu_for_a_large_error():
    """A large relative error: the error system's Gramian alone certifies it to four digits (the cross
    term of the tail bounded by Cauchy-Schwarz), no LU beyond the model's cached Gramian factors;
    rtol 1e-8 adds at most one LU per pole pair."""
    fom = ms.models.dsms(g=600)
    rom = _reduce(fom, "bt", 5)
    ms.analysis.h2_norm(fom)
    value4, d4 = _h2(fom, rom, rtol=1e-4)
    assert d4["method"] == "error-gramian" and d4["lu_count"] == 0 and d4["trusted"] and d4["rtol_met"]
    value, d = _h2(fom, rom)
    assert d["trusted"] and d["rtol_met"] and d["lu_count"] <= int(np.sum(rom.poles().imag >= 0))
    assert abs(value - value4) <= d["floor"] + d4["floor"]
    ref, dp = _h2(fom, rom, method="pole-residue")
    assert abs(value - ref) <= d["floor"] + dp["floor"]


def test_negative_square_is_flagged_not_clipped():
    """The pole-residue formula's square can come out negative (cancellation): the value 0 is flagged."""
    fom = ms.models.dsms(g=40)
    rom = _reduce(fom, "bt", 26)  # ||E|| / ||T|| ~ 1e-12
    with pytest.warns(ms.AccuracyWarning):
        value, d = ms.analysis.h2_error(fom, rom, method="pole-residue", details=True)
    if d["squared"] < 0:
        assert d["negative"] and not d["trusted"] and value == 0.0 and d["rel_floor"] == np.inf
    else:
        assert not d["negative"] and (not d["trusted"] or d["rel_floor"] <= 1e-4)
    auto, da = _h2(fom, rom)
    assert not da["negative"] and auto > 0


REDUCERS = [("bt", {}), ("bt", {"form": "vv"}), ("irka", {}), ("irka-fo", {}), ("bt", {"form": "fv"})]


@st.composite
def cases(draw):
    n1 = draw(st.integers(16, 30))
    kw = dict(n1=n1, n2=draw(st.integers(1, 4)), m=draw(st.integers(1, 3)), p=draw(st.integers(1, 3)),
              seed=draw(st.integers(0, 2**31 - 1)), zeta=float(10 ** draw(st.floats(-2, -1))),
              damping=draw(st.sampled_from(["rayleigh", "dashpots"])))
    method, opts = draw(st.sampled_from(REDUCERS))
    r = draw(st.integers(2, 12))
    return kw, method, opts, r


@pytest.mark.stress
@settings(max_examples=20, deadline=None, derandomize=True, phases=[Phase.explicit, Phase.generate],
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(cases())
def test_every_floor_bounds_its_error_on_random_models(case):
    kw, method, opts, r = case
    fom = ms.models.random_constrained(**kw)
    rom = _reduce(fom, method, r, **opts)
    if not rom.is_stable():
        return
    value, d = _h2(fom, rom)
    ref, acc = reference(fom, rom)
    err = abs(value - ref)
    assert err <= d["floor"] + acc * ref, (d["method"], err / ref, d["rel_floor"])
    if d["trusted"]:
        assert d["rel_floor"] <= 1e-4 and err <= (1e-4 + acc) * ref
    # every route that ran states a floor that bounds its own value's error
    for key in ("error_gramian", "pole_residue"):
        rec = d.get(key)
        if rec and np.isfinite(rec.get("floor_squared", np.inf)) and rec.get("squared") is not None:
            assert abs(rec["squared"] - ref * ref) <= rec["floor_squared"] + 2 * acc * ref * ref


@pytest.fixture(scope="module")
def large_order_models():
    """{spec: (model, its dense H2 norm)}, each built once for the module: the three tcom(60) cases share the
    model's LR-ADI factors (as reductions of one model do) and its dense Lyapunov norm (the reference's
    ||T||, 350 hidden states)."""
    return {}


@pytest.mark.parametrize("spec,method,opts,r", [
    pytest.param("tcom:nc=60", "bt", {}, 60, marks=pytest.mark.slow),   # 60 states, 60 poles, ||E|| / ||T|| ~ 1e-8
    pytest.param("tcom:nc=60", "irka-fo", {}, 30, marks=pytest.mark.slow),
    pytest.param("tcom:nc=60", "bt", {"form": "vv"}, 20, marks=pytest.mark.slow),  # 40 states
    ("dsms:g=60", "irka", {}, 8),
], ids=["tcom60-bt60", "tcom60-irkafo30", "tcom60-vv20", "dsms60-irka8"])   # tcom60: 6.5 to 9 s of CPU each
def test_trusted_values_within_their_floor_at_large_orders(spec, method, opts, r, large_order_models):
    """Against the cancellation-free quadrature converged at rtol 1e-11 (another route: no Gramian, no
    modal form), and the dense Lyapunov reference where it is reliable."""
    if spec not in large_order_models:
        fom = ms.models.parse(spec)
        large_order_models[spec] = fom, lyap_h2(*hidden_ss(fom))
    fom, norm = large_order_models[spec]
    rom = _reduce(fom, method, r, **opts)
    value, d = _h2(fom, rom)
    q, dq = _h2(fom, rom, method="quadrature", rtol=1e-11, max_nodes=20000)
    assert dq["quadrature"]["converged"] and dq["quadrature"]["covered"]
    assert abs(value - q) <= d["floor"] + dq["floor"]
    assert d["trusted"] == (d["rel_floor"] <= 1e-4 and d["consistent"] and not d["negative"])
    assert d["trusted"] and d["rtol_met"]
    # and against the dense Lyapunov reference of the error system (up to 410 states here), to its accuracy
    ref, acc = dense_reference(fom, rom, norm)
    assert abs(value - ref) <= d["floor"] + acc * ref
