r"""The ``time`` scene's settings: their keys, defaults and validators, and their check on the model.

What a time scene may say (input, horizon, step, scheme, rom_method, direction, channel) and
how it is checked before anything runs (:func:`resolve`, kept in the spec memo) are here; the
tasks that simulate are :mod:`morsuite.studies.timedomain`, which re-exports these names.
This module imports only :mod:`morsuite.studies.checks` (and, to check an input, :mod:`morsuite.analysis`):
the spec and the scene kinds validate with it.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from ..errors import InputError
from .checks import choice_of, finite_list, positive_float, positive_int

__all__ = ["TIME_KEYS", "INPUT_KINDS", "SCHEMES", "ROM_METHODS", "resolve", "settings", "SIM_ARRAYS",
           "SIM_ERROR_ARRAYS", "ERROR_COLUMNS"]

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
