"""How a study asks for exact error norms: their kinds, the option tables, and their validation.

The option tables repeat the keyword options of :func:`morsuite.analysis.h2_error` and
:func:`morsuite.analysis.hinf_error` with the same defaults (``tests/test_studies_norms_time.py``
checks that they agree); the tasks that compute the norms are :mod:`morsuite.studies.norms`.
This module imports only :mod:`morsuite.studies.checks`: the spec and the scene kinds validate with it.
"""

from __future__ import annotations

from numbers import Real

from .checks import choice_of, float_in_01, int_at_least, nonnegative_int, positive_int, subset_of

__all__ = ["NORM_KINDS", "NORM_OPTIONS", "NORM_MEASURES", "ADI_KEYS", "full_options", "norms_of"]

NORM_KINDS = ("h2", "hinf")
#: measure of a scene -> (norm kind, relative?)
NORM_MEASURES = {"h2": ("h2", False), "h2_rel": ("h2", True), "hinf": ("hinf", False), "hinf_rel": ("hinf", True)}
#: the LR-ADI options of the Gramian factors (morsuite.linalg.gramians.ADI_DEFAULTS)
ADI_KEYS = ("tol", "maxiter", "shifts", "num_shifts", "selection", "refine", "shift_reuse", "lu_pool_mib",
            "compress_tol", "pool_full_reuse")


def _nonnegative_below_1(ctx, where, value):
    """``float(value)`` if it lies in [0, 1)."""
    if isinstance(value, bool) or not isinstance(value, Real) or not (0 <= value < 1):
        ctx.fail(where, f"expected a number in [0, 1); got {value!r}")
    return float(value)


def _nonnegative(ctx, where, value):
    """``float(value)`` if it is a finite number >= 0."""
    if isinstance(value, bool) or not isinstance(value, Real) or not (0 <= value < float("inf")):
        ctx.fail(where, f"expected a finite number >= 0; got {value!r}")
    return float(value)


def _adi(ctx, where, value):
    if value is None:
        return None
    ctx.keys(where, value, ADI_KEYS)
    checks = {"tol": float_in_01, "maxiter": positive_int, "num_shifts": positive_int, "refine": nonnegative_int,
              "shift_reuse": _nonnegative_below_1, "lu_pool_mib": _nonnegative, "compress_tol": _nonnegative_below_1,
              "pool_full_reuse": _nonnegative_below_1}
    out = {}
    for k, v in value.items():
        out[k] = checks[k](ctx, f"{where}.{k}", v) if k in checks else v
    return out


def _band_grid(ctx, where, value):
    """None, or ``[lo, hi, n]``: a band response's grid (0 < lo < hi, an integer n >= 2)."""
    if value is None:
        return None
    ok = (isinstance(value, (list, tuple)) and len(value) == 3
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
          and isinstance(value[2], int) and value[2] >= 2 and 0 < value[0] < value[1] < float("inf"))
    if not ok:
        ctx.fail(where, f"expected [lo, hi, n] with 0 < lo < hi and an integer n >= 2; got {value!r}")
    return [float(value[0]), float(value[1]), int(value[2])]


def _skip_factor(ctx, where, value):
    """A number in [0, 1)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < 1:
        ctx.fail(where, f"expected a number in [0, 1); got {value!r}")
    return float(value)


def _flag(ctx, where, value):
    """True or False."""
    if not isinstance(value, bool):
        ctx.fail(where, f"expected true or false; got {value!r}")
    return value


#: kind -> option -> (default, validator); the keyword options of h2_error / hinf_error
NORM_OPTIONS = {
    "h2": {"method": ("auto", choice_of(("auto", "error-gramian", "pole-residue", "quadrature"))), "rtol": (1e-8, float_in_01),
           "max_nodes": (1500, int_at_least(15)), "refine": (1, nonnegative_int), "adi": (None, _adi)},
    "hinf": {"max_lus": (190, int_at_least(4)), "grid_lus": (120, positive_int), "rtol": (1e-10, float_in_01),
             "per_decade": (8, positive_int), "refine": (1, nonnegative_int), "n_peaks": (8, positive_int),
             "adi": (None, _adi), "certify_dim": (1000, nonnegative_int), "certify_tol": (1e-6, float_in_01),
             "certify_lus": (100, int_at_least(4)), "band_grid": (None, _band_grid),
             "skip_factor": (0.0, _skip_factor), "screen": (False, _flag)},
}


def full_options(ctx, where, kind, given) -> dict:
    """Every option of ``kind`` with the defaults filled in, each value checked."""
    table = NORM_OPTIONS[kind]
    given = {} if given is None else given
    ctx.keys(where, given, tuple(table))
    return {k: (check(ctx, f"{where}.{k}", given[k]) if k in given else default)
            for k, (default, check) in table.items()}


def norms_of(ctx, data):
    """The top-level ``norms`` (kinds for every reduction) and ``norm_options`` (every kind, filled in)."""
    kinds = tuple(subset_of(NORM_KINDS)(ctx, "norms", data.get("norms", [])))
    given = data.get("norm_options", {})
    ctx.keys("norm_options", given, NORM_KINDS)
    return kinds, {k: full_options(ctx, f"norm_options.{k}", k, given.get(k)) for k in NORM_KINDS}
