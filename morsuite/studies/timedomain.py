r"""Time-domain comparisons in a study: the ``time`` scene's settings and the tasks of the graph.

A ``time`` scene simulates the full model and the reduced models of its methods at one r
from rest (:func:`morsuite.analysis.simulate`) and shows :math:`y` and :math:`y_r`, and
:math:`\|y(t) - y_r(t)\|_2`::

    [[scenes]]
    name = "tcom_r30_step"
    kind = "time"
    model = "tcom"
    methods = ["bt", "irka"]
    r = 30
    input = "step"            # "impulse", "chirp:omega0=0.01,omega1=1", "multisine:omegas=0.1;0.5",
                              # "csv:PATH" (columns t, u1..um; relative to root), or a table
                              # { kind = "chirp", omega0 = 0.01, omega1 = 1.0 }
    horizon = 600.0           # s; default 2 pi / (lower end of the model's band)
    step = 0.3                # s; default 0.3 / (upper end of the band)
    scheme = "trapezoidal"    # or "backward-euler"
    rom_method = "scheme"     # or "control" (python-control's forced_response)
    direction = [1.0, 0.0]    # MIMO: the input direction (default ones(m))
    channel = 1               # the output shown in the figure of y (all are in its CSV files)

The input, horizon and step are checked on the model before anything runs (a step larger
than the horizon, a direction of the wrong length, a CSV with the wrong number of
channels or non-finite samples are refused, naming the scene); the check is kept in the
spec memo, so a cached study imports no numerical code. The settings' table and that check
are :mod:`morsuite.studies.time_options` (re-exported here); this module holds the tasks.

Artifacts (cached): the full model's simulation per (model, input, horizon, step, scheme,
direction), shared by every method and scene that simulates the same (like the full
response per grid): one sparse LU and one solve per step; and per (reduction, simulation,
rom_method) the reduced output and the errors of :func:`morsuite.analysis.output_errors`
(``max_output_error``, ``l2_output_error``, their relative versions) with the growth flag
of an unstable reduced model (simulated all the same, with a warning).
"""


from __future__ import annotations

import time
import warnings

import numpy as np

from .task_common import CAUGHT, model_of as _model, rom_from_payload, stamp as _stamp
from .time_options import (ERROR_COLUMNS, INPUT_KINDS, ROM_METHODS, SCHEMES, SIM_ARRAYS, SIM_ERROR_ARRAYS,
                           TIME_KEYS, resolve, settings)

__all__ = ["TIME_KEYS", "INPUT_KINDS", "SCHEMES", "ROM_METHODS", "resolve", "settings", "full_simulation",
           "rom_simulations", "SIM_ARRAYS", "SIM_ERROR_ARRAYS", "ERROR_COLUMNS"]


def full_simulation(source: str, setup: dict, key: str, run_by: str = "") -> dict:
    """The full model's output ``y`` on ``t`` for the settings ``setup`` (task).

    Cost: one sparse LU of the saddle-point matrix and one solve per step.
    """
    from ..analysis.compare import time_input, time_response

    base = {"kind": "simulation", "key": key, "setup": setup, "cached": False, "scheduler": run_by}
    fom = _model(source)
    t0 = time.perf_counter()
    try:
        t, u, _ = time_input(fom.band, fom.m, setup["input"], horizon=setup["horizon"], step=setup["step"],
                             direction=setup["direction"])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # recorded in rec["warnings"]
            y, rec = time_response(fom, t, u, scheme=setup["scheme"])
    except CAUGHT as exc:
        return {**base, "error": f"{type(exc).__name__}: {exc}", "time_s": time.perf_counter() - t0, **_stamp()}
    return {**base, **rec, "t": t, "y": y, "model": fom.name, **_stamp()}


def rom_simulations(sim: dict, band, m: int, rom_method: str, rs, keys: dict, run_by: str, *rom_dicts) -> dict:
    """Reduced outputs ``y_r`` and their errors against ``sim`` (the full simulation) for each r (task).

    A reduced model with poles in the right half-plane is simulated all the same:
    ``growth`` is True and the record holds the warning. Cost: one dense LU of
    size 2r and a product per step (``rom_method="scheme"``).
    """
    from ..analysis import output_errors
    from ..analysis.compare import time_input, time_response

    roms = {}
    for d in rom_dicts:
        roms.update(d or {})
    setup = sim["setup"]
    out, u = {}, None
    for r in rs:
        base = {"kind": "sim_error", "key": keys[r], "rom_method": rom_method, "cached": False, "scheduler": run_by}
        entry = roms.get(r)
        why = ("full model: " + sim["error"]) if "error" in sim else \
            ("no reduced model" if entry is None else entry.get("error"))
        if why is not None:
            out[r] = {**base, "error": why, **_stamp()}
            continue
        t0 = time.perf_counter()
        try:
            if u is None:
                t, u, _ = time_input(band, m, setup["input"], horizon=setup["horizon"], step=setup["step"],
                                     direction=setup["direction"])
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # recorded in rec["warnings"]
                y_r, rec = time_response(rom_from_payload(entry["rom"]), t, u, scheme=setup["scheme"],
                                         rom_method=rom_method)
            errs = output_errors(np.asarray(sim["y"]), y_r, t)
        except CAUGHT as exc:
            out[r] = {**base, "error": f"{type(exc).__name__}: {exc}", "time_s": time.perf_counter() - t0,
                      **_stamp()}
            continue
        out[r] = {**base, **rec, **errs, "y_r": y_r, **_stamp()}
    return out
