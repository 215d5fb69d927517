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
spec memo, so a cached study imports no numerical code.

Artifacts (cached): the full model's simulation per (model, input, horizon, step, scheme,
direction), shared by every method and scene that simulates the same (like the full
response per grid): one sparse LU and one solve per step; and per (reduction, simulation,
rom_method) the reduced output and the errors of :func:`morsuite.analysis.output_errors`
(``max_output_error``, ``l2_output_error``, their relative versions) with the growth flag
of an unstable reduced model (simulated all the same, with a warning).
"""

from __future__ import annotations

import hashlib
import time
import warnings
from pathlib import Path

import numpy as np

from ..errors import InputError
from .checks import choice_of, finite_list, positive_float, positive_int
from .tasks import CAUGHT, _model, _stamp, rom_from_payload

__all__ = ["TIME_KEYS", "INPUT_KINDS", "SCHEMES", "ROM_METHODS", "resolve", "settings", "full_simulation",
           "rom_simulations", "SIM_ARRAYS", "SIM_ERROR_ARRAYS", "ERROR_COLUMNS"]

INPUT_KINDS = ("step", "impulse", "chirp", "multisine", "csv")
#: morsuite.analysis.timestep.SCHEMES and the rom_method choices of morsuite.analysis.simulate
SCHEMES = ("trapezoidal", "backward-euler")
ROM_METHODS = ("scheme", "control")
SIM_ARRAYS = ("t", "y")
SIM_ERROR_ARRAYS = ("y_r",)
#: the time-domain columns of a summary row, from a reduction's entry
ERROR_COLUMNS = ("max_output_error", "l2_output_error", "max_output_rel_error", "l2_output_rel_error", "growth")


def _input(ctx, where, value):
    """An input spec: a string ``KIND[:params]`` or a table ``{ kind = ..., ... }``, KIND known."""
    if isinstance(value, str) and value:
        kind = value.partition(":")[0]
    elif isinstance(value, dict):
        kind = value.get("kind")
        if kind is None:
            ctx.fail(where, f"an input table needs 'kind' (one of {', '.join(INPUT_KINDS)})")
    else:
        ctx.fail(where, f"expected an input spec such as \"step\" or {{ kind = \"chirp\", ... }}; got {value!r}")
    ctx.choice(f"{where} (input kind)", kind, INPUT_KINDS)
    return value


#: scene key -> (default, validator) of the time scene
TIME_KEYS = {"input": ("step", _input), "horizon": (None, positive_float), "step": (None, positive_float),
             "scheme": ("trapezoidal", choice_of(SCHEMES)), "rom_method": ("scheme", choice_of(ROM_METHODS)),
             "direction": (None, finite_list), "channel": (1, positive_int)}


def _csv_path(spec):
    if isinstance(spec, str):
        return spec.partition(":")[2] if spec.startswith("csv:") else None
    return spec.get("path") if spec.get("kind") == "csv" else None


def resolve(ctx, where, params: dict, model, root: Path, memo=None) -> None:
    """Check a time scene's settings on its model and fill in the defaults (in ``params``).

    A CSV input's path becomes absolute and its SHA-256 part of the settings. The
    check (:func:`morsuite.analysis.compare.time_input` on the whole grid) is kept in
    ``memo`` (a :class:`~morsuite.studies.memo.SpecMemo`).
    """
    spec, sha = params["input"], None
    path = _csv_path(spec)
    if path is not None:
        p = Path(path)
        p = (p if p.is_absolute() else root / p).resolve()
        if not p.is_file():
            ctx.fail(f"{where}.input", f"input CSV {str(p)!r} does not exist")
        sha = hashlib.sha256(p.read_bytes()).hexdigest()
        spec = f"csv:{p}" if isinstance(spec, str) else {**spec, "path": str(p)}
    if params["channel"] > model.p:
        ctx.fail(f"{where}.channel", f"channel {params['channel']} does not exist: model {model.alias!r} has "
                                     f"p = {model.p} outputs")
    material = {"model_id": model.model_id, "band": list(model.band), "m": model.m, "input": spec,
                "input_sha256": sha, "horizon": params["horizon"], "step": params["step"],
                "direction": params["direction"]}
    hit = memo.lookup("time", material, "morsuite.analysis") if memo is not None else None
    if hit is None:
        from ..analysis.compare import time_input

        try:
            _, _, setup = time_input(model.band, model.m, spec, horizon=params["horizon"], step=params["step"],
                                     direction=params["direction"])
        except InputError as exc:
            ctx.fail(where, f"time-domain input on model {model.alias!r} ({model.name}): {exc}")
        hit = {k: setup[k] for k in ("horizon", "step", "steps")}
        if memo is not None:
            memo.store("time", material, hit, "morsuite.analysis.compare")
    params.update(input=spec, input_sha256=sha, horizon=float(hit["horizon"]), step=float(hit["step"]),
                  steps=int(hit["steps"]))


def settings(params: dict) -> dict:
    """What determines the full model's simulation of a resolved time scene."""
    return {k: params[k] for k in ("input", "input_sha256", "horizon", "step", "scheme", "direction")}


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
