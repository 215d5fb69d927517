r"""The ``tolerance`` scene's settings: their keys, defaults and validators.

A tolerance scene asks, for each of its methods, the smallest reduced model whose error meets
each tolerance of ``tol`` (:mod:`morsuite.analysis.tolerance`)::

    [[scenes]]
    name = "to_reach"
    kind = "tolerance"
    model = "model"
    grid = "band"            # the band grid of error = "band" (none for "h2", "hinf")
    methods = ["bt", "krylov", "modal"]
    tol = [0.01, 0.001]      # relative errors in (0, 1)
    error = "band"           # band (band max error / band peak), h2, hinf (certified upper bound)
    budget_lus = 400         # optional: each method's LU budget
    budget_s = 900           # optional: each method's time budget (s)
    max_states = 400         # optional: the largest first-order states tried
    save_roms = true         # optional: write each chosen model (.npz, .mat, .json) into OUT/NAME/roms/

No ``r``: the orders are what the search finds. This module imports only
:mod:`morsuite.studies.checks`: the spec and the scene kinds validate with it; the task that
searches is :mod:`morsuite.studies.tolerance`.
"""

from __future__ import annotations

from numbers import Real

from .checks import choice_of, positive_float, positive_int

__all__ = ["TOL_KEYS", "TOL_MEASURES", "tol_values", "settings", "SETTING_KEYS"]

#: the error measures of a tolerance (morsuite.analysis.tolerance.MEASURES)
TOL_MEASURES = ("band", "h2", "hinf")


def tol_values(ctx, where, value):
    """One relative tolerance or a non-empty list of them, each in (0, 1); returned as a list, tightest last."""
    vals = value if isinstance(value, list) else [value]
    if not vals or any(isinstance(v, bool) or not isinstance(v, Real) or not (0 < v < 1) for v in vals):
        ctx.fail(where, f"expected a relative tolerance in (0, 1) or a non-empty list of them; got {value!r}")
    if len(set(vals)) != len(vals):
        ctx.fail(where, f"a tolerance is given twice in {value!r}")
    return sorted((float(v) for v in vals), reverse=True)


def _flag(ctx, where, value):
    if not isinstance(value, bool):
        ctx.fail(where, f"expected true or false; got {value!r}")
    return value


tol_values.describe = "a number in (0, 1) or a list of them"
_flag.describe = "true or false"

#: scene key -> (default, validator) of the tolerance scene
TOL_KEYS = {"tol": (None, tol_values), "error": ("band", choice_of(TOL_MEASURES)), "budget_lus": (None, positive_int),
            "budget_s": (None, positive_float), "max_states": (None, positive_int), "save_roms": (False, _flag)}

#: the settings that decide a search's result (its cache key), besides the model, the method and the grid
SETTING_KEYS = ("tol", "error", "budget_lus", "budget_s", "max_states")


def settings(params: dict) -> dict:
    """The scene's settings that decide a search (:data:`SETTING_KEYS`), defaults filled in."""
    return {k: params.get(k, TOL_KEYS[k][0]) for k in SETTING_KEYS}
