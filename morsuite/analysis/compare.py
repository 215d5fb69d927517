r"""One reduced model against its full model, as plain records: exact error norms and time-domain errors.

The command line (``morsuite reduce``, ``morsuite simulate``) and the study runner
report the same numbers through these functions, so that a number in a JSON line
and in a study summary come from the same calls with the same options.

:func:`model_norm`, :func:`error_norm`
    :math:`\|T\|` and :math:`\|T - T_r\|` in the H2 norm (``"h2"``,
    :func:`~morsuite.analysis.h2_norm`, :func:`~morsuite.analysis.h2_error`) or the
    H-infinity norm (``"hinf"``, :func:`~morsuite.analysis.hinf_norm`,
    :func:`~morsuite.analysis.hinf_error`), with a compact record of how the value
    was obtained: ``route``, ``lu_count``, ``floor`` / ``rel_floor`` (estimated
    accuracy), ``trusted``, ``time_s`` and the warnings issued.
:func:`error_norms`
    Both kinds and the relative errors
    :math:`\|T - T_r\|_{\mathcal H_2}/\|T\|_{\mathcal H_2}`,
    :math:`\|T - T_r\|_{\mathcal H_\infty}/\|T\|_{\mathcal H_\infty}` as flat keys
    ``h2_error, h2_rel_error, h2_route, h2_trusted, ..., hinf_error, ...``.
:func:`time_input`, :func:`time_response`
    The time grid and input of a time-domain comparison (defaults from the model's
    band, :func:`~morsuite.analysis.signals.default_horizon_step`) and one
    simulation with its record; :func:`~morsuite.analysis.output_errors` compares two.

The H-infinity search starts from the model's resonances when Gramian factors of the
model are cached (:mod:`morsuite.analysis.hinf`). So that its value does not depend on
what ran before in the same process (a ``bt`` reduction, an ``h2_norm``), the H-infinity
functions here compute the factors first (:func:`~morsuite.linalg.gramians.gramian_factors`,
once per model and ADI options, shared with ``bt`` and the H2 norm).

Warnings of the underlying calls are recorded in the record's ``warnings`` (as
``"Category: message"``) and issued again to the caller.
"""

from __future__ import annotations

import inspect
import time
import warnings

import numpy as np

from ..errors import InputError, MorsuiteError, OptionError
from ..linalg.gramians import gramian_factors
from . import signals
from ..models.rigid import flexible_part, rigid_body_modes
from ..norms._common import adi_options
from ..norms.h2 import h2_error, h2_norm
from .hinf import hinf_error, hinf_norm
from .simulate import simulate

__all__ = ["NORM_KINDS", "HINF_ROUTES", "model_norm", "error_norm", "error_norms", "norm_options", "time_input",
           "time_response", "MAX_STEPS"]

NORM_KINDS = ("h2", "hinf")
_ERROR = {"h2": h2_error, "hinf": hinf_error}
#: a time grid longer than this is refused (the output alone would take p x 80 MB)
MAX_STEPS = 10_000_000


def norm_options(kind: str, options=None) -> dict:
    """Every option of :func:`~morsuite.analysis.h2_error` / :func:`~morsuite.analysis.hinf_error`
    for ``kind``, defaults filled in from their signatures; unknown names refused."""
    if kind not in NORM_KINDS:
        raise OptionError(f"norm must be one of {', '.join(map(repr, NORM_KINDS))}; got {kind!r}")
    options = {} if options is None else options
    if not isinstance(options, dict):
        raise OptionError(f"options of the {kind} norm must be a dict; got {type(options).__name__}")
    params = {n: p.default for n, p in inspect.signature(_ERROR[kind]).parameters.items()
              if p.kind is inspect.Parameter.KEYWORD_ONLY and n != "details"}
    unknown = sorted(set(options) - set(params))
    if unknown:
        raise OptionError(f"unknown option(s) {', '.join(map(repr, unknown))} of the {kind} norm; valid: "
                          f"{', '.join(params)}")
    return {**params, **options}


def _captured(fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` and the list of its warnings as text (the warnings are issued again)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*args, **kwargs)
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return out, [f"{w.category.__name__}: {w.message}" for w in caught]


def _prepare_hinf(fom, opts):
    # the start grid of the Hinf search uses cached Gramian factors: make sure they exist, for the model the
    # search runs on: a free-floating model's flexible part (its own factors cannot converge, a pole at 0:
    # the LR-ADI ran to maxiter, 18 s on dsms:g=40,free=true, for factors nothing read)
    if rigid_body_modes(fom).k:
        try:
            fom = flexible_part(fom)
        except MorsuiteError:  # coupled damping: hinf_error says why
            return
    gramian_factors(fom, **adi_options(opts.get("adi")))


#: routes of an H-infinity value: a lower bound alone, or enclosed by a certified upper bound
HINF_ROUTES = ("peak search (lower bound)", "peak search + level-set certificate")


def _hinf_bounds(value, d) -> dict:
    """Route, bounds and flags of an H-infinity record: ``trusted`` is ``certified`` (the value is the
    lower bound, ``floor`` the certified gap ``upper_bound - lower_bound``)."""
    ok = bool(d.get("certified", False))
    up = d.get("upper_bound")
    floor = float(up - value) if ok and up is not None and np.isfinite(value) else None
    return {"route": HINF_ROUTES[ok], "lower_bound": d.get("lower_bound", value), "upper_bound": up,
            "certified": ok, "trusted": ok, "floor": floor,
            "rel_floor": floor / value if floor is not None and value > 0 else (0.0 if floor == 0 else None)}


def model_norm(fom, kind: str, options=None) -> dict:
    r""":math:`\|T\|_{\mathcal H_2}` or :math:`\|T\|_{\mathcal H_\infty}` of the model, with its record.

    Parameters
    ----------
    fom : Index3Model
    kind : {"h2", "hinf"}
    options : dict, optional
        Options of :func:`~morsuite.analysis.h2_error` (only ``adi`` matters for the
        norm) or :func:`~morsuite.analysis.hinf_error` (all but ``details``).

    Returns
    -------
    dict
        ``value``, ``kind``, ``route``, ``lu_count``, ``trusted``, ``rel_floor``,
        ``time_s``, ``warnings``, ``options``; for ``"hinf"`` also ``lower_bound``,
        ``upper_bound`` (None where not certified) and ``certified`` (``trusted`` is
        ``certified``; ``value`` is the lower bound). For a model with rigid-body modes
        (infinite norms) the norm of its flexible part
        (:func:`~morsuite.models.rigid.flexible_part`), with ``part`` = ``"flexible"`` and
        ``rigid_modes``: relative errors are then relative to the flexible part.

    Notes
    -----
    Cost: the LR-ADI pair of Gramian factors (once per model and ADI options,
    shared with ``bt``); ``"hinf"`` adds at most ``max_lus`` LUs (default 190),
    cached per model.
    """
    opts = norm_options(kind, options)
    t0 = time.perf_counter()
    part = {}
    if rigid_body_modes(fom).k:  # a pole at 0: the norm of the flexible part, where T - T_r lives
        part = {"part": "flexible", "rigid_modes": rigid_body_modes(fom).k}
        fom = flexible_part(fom)
    if kind == "h2":
        (value, d), warned = _captured(h2_norm, fom, adi=opts["adi"], details=True)
        rec = {"route": "gramian", "lu_count": d["lu_count"], "trusted": d["trusted"], "rel_floor": d["rel_floor"],
               "factor_rank": d["factor_rank"], "adi_converged": d["adi_converged"]}
    else:
        _prepare_hinf(fom, opts)
        (value, d), warned = _captured(hinf_norm, fom, details=True, **opts)
        rec = {"lu_count": d["lu_count"], **_hinf_bounds(value, d), "peak_frequency": d["peak_frequency"],
               "samples": d.get("samples")}
    return {"value": float(value), "kind": kind, **rec, **part, "time_s": time.perf_counter() - t0,
            "warnings": warned, "options": opts}


def error_norm(fom, rom, kind: str, options=None) -> dict:
    r""":math:`\|T - T_r\|` in the H2 or H-infinity norm, with its record.

    Parameters
    ----------
    fom : Index3Model
    rom : SecondOrderROM or FirstOrderROM
    kind : {"h2", "hinf"}
    options : dict, optional
        Options of :func:`~morsuite.analysis.h2_error` or :func:`~morsuite.analysis.hinf_error`.

    Returns
    -------
    dict
        ``value`` (``inf`` for an unstable reduced model, with a warning and
        ``reason``), ``route`` (``"error-gramian"``, ``"pole-residue"`` or ``"quadrature"`` for H2; for
        H-infinity one of :data:`HINF_ROUTES`), ``lu_count``, ``floor``,
        ``rel_floor``, ``trusted`` (False: the value is not accurate to four digits,
        never to be shown as exact), ``nodes`` (H2 quadrature), ``peak_frequency``
        (H-infinity), ``time_s``, ``warnings``, ``options``. H-infinity: ``value`` is
        the peak found, a lower bound (``lower_bound``); ``upper_bound`` and
        ``certified`` come from the level-set test (None and False above
        ``certify_dim``); ``trusted`` is ``certified`` and ``floor`` the gap between
        the bounds.

    Raises
    ------
    ShapeError, InputError
        As :func:`~morsuite.analysis.h2_error`: other input/output dimensions, a
        non-finite reduced model.
    """
    opts = norm_options(kind, options)
    t0 = time.perf_counter()
    if kind == "hinf":
        _prepare_hinf(fom, opts)
    (value, d), warned = _captured(_ERROR[kind], fom, rom, details=True, **opts)
    rec = {"value": float(value), "kind": kind, "lu_count": int(d.get("lu_count") or 0), "reason": d.get("reason")}
    if kind == "h2":
        rec.update(route=d.get("method"), trusted=bool(d.get("trusted", False)), floor=d.get("floor"),
                   rel_floor=d.get("rel_floor"), rtol_met=d.get("rtol_met"), nodes=d.get("nodes", 0))
    else:
        rec.update(**_hinf_bounds(value, d), peak_frequency=d.get("peak_frequency"), samples=d.get("samples"))
        if not np.isfinite(value):
            rec["route"] = None
    return {**rec, "time_s": time.perf_counter() - t0, "warnings": warned, "options": opts}


def error_norms(fom, rom, kinds=NORM_KINDS, options=None) -> dict:
    r"""Absolute and relative error norms of ``rom`` as flat keys (the ``morsuite reduce --json`` fields).

    Parameters
    ----------
    fom, rom
        The model and a reduced model of it.
    kinds : sequence of {"h2", "hinf"}
        Which norms (default both).
    options : dict, optional
        ``{"h2": {...}, "hinf": {...}}``: options of each kind (:func:`error_norm`).

    Returns
    -------
    dict
        For each kind K: ``K_error``, ``K_rel_error`` (divided by the model's norm
        of the same kind), ``K_norm``, ``K_route``, ``K_trusted``, ``K_lu_count``
        (LUs of the error and of the model's norm, the Gramian factors included
        when this call computed them), ``K_time_s``; ``norm_warnings`` (list).
        H2: ``h2_floor`` and ``h2_norm_floor``, the estimated absolute accuracy of the error
        and of the norm. H-infinity: ``hinf_error`` and ``hinf_norm`` are the peaks found (lower
        bounds); ``hinf_upper_bound`` and ``hinf_norm_upper_bound`` (None where not certified),
        ``hinf_certified`` and ``hinf_norm_certified`` say whether each is enclosed by the
        level-set test. ``norm_options``: per kind, every option the error was computed with
        (defaults filled in), so that it can be computed again alike (``morsuite verify``).
    """
    options = {} if options is None else options
    bad = sorted(set(options) - set(NORM_KINDS))
    if bad:
        raise OptionError(f"options has unknown norm(s) {bad}; valid: {', '.join(NORM_KINDS)}")
    out, warned, used = {}, [], {}
    for kind in kinds:
        if kind not in NORM_KINDS:
            raise OptionError(f"norm must be one of {', '.join(map(repr, NORM_KINDS))}; got {kind!r}")
        e = error_norm(fom, rom, kind, options.get(kind))
        n = model_norm(fom, kind, options.get(kind))
        rel = e["value"] / n["value"] if n["value"] > 0 else np.inf
        out.update({f"{kind}_error": e["value"], f"{kind}_rel_error": float(rel), f"{kind}_norm": n["value"],
                    f"{kind}_route": e["route"], f"{kind}_trusted": bool(e["trusted"] and n["trusted"]),
                    f"{kind}_lu_count": e["lu_count"] + n["lu_count"], f"{kind}_time_s": e["time_s"] + n["time_s"]})
        if kind == "h2":  # the stated accuracies (absolute) of the error and of the model's norm
            out.update(h2_floor=e["floor"], h2_norm_floor=_floor(n))
        if kind == "hinf":
            # the value is a lower bound; an upper bound where the level-set test certified one
            out.update(hinf_peak_frequency=e.get("peak_frequency"), hinf_certified=bool(e["certified"]),
                       hinf_upper_bound=e["upper_bound"], hinf_norm_certified=bool(n["certified"]),
                       hinf_norm_upper_bound=n["upper_bound"])
        used[kind] = e["options"]
        warned += e["warnings"] + n["warnings"]
    out["norm_warnings"] = warned
    out["norm_options"] = used
    return out


def _floor(rec):
    """The absolute floor of a model norm's record (``rel_floor`` times the value), None where unknown."""
    rel = rec.get("rel_floor")
    return None if rel is None else float(rel) * rec["value"]


def time_input(band, m: int, input="step", *, horizon=None, step=None, direction=None):
    r"""Time grid and input samples of a time-domain comparison.

    Parameters
    ----------
    band : (float, float)
        The model's band :math:`[\omega_{lo}, \omega_{hi}]` (rad/s): the defaults
        ``horizon`` :math:`= 2\pi/\omega_{lo}` and ``step`` :math:`= 0.3/\omega_{hi}`
        (:func:`~morsuite.analysis.signals.default_horizon_step`).
    m : int
        Number of inputs.
    input : str or dict
        Input spec of :func:`~morsuite.analysis.signals.make` (default ``"step"``).
    horizon, step : float, optional
        Simulated time and constant step (s).
    direction : sequence of m floats, optional
        Input direction of a generated signal (default ones(m)).

    Returns
    -------
    t : ndarray, u : ndarray (len(t), m) or Impulse, setup : dict
        ``setup``: ``input``, ``horizon``, ``step``, ``steps``, ``direction``.

    Raises
    ------
    InputError
        A step larger than the horizon, more than :data:`MAX_STEPS` steps, a bad
        input spec or direction.
    """
    h_def, s_def = signals.default_horizon_step(band)
    horizon = h_def if horizon is None else signals._positive("horizon", horizon)
    step = s_def if step is None else signals._positive("step", step)
    if step <= horizon and horizon / step > MAX_STEPS:
        raise InputError(f"horizon {horizon:g} / step {step:g} = {horizon / step:.3g} steps; at most {MAX_STEPS:,} "
                         "are simulated (a larger step or a shorter horizon)")
    t = signals.time_grid(horizon, step)
    u = signals.make(input, t, m, direction=direction)
    setup = {"input": input, "horizon": float(horizon), "step": float(step), "steps": int(t.size - 1),
             "direction": None if direction is None else [float(b) for b in np.ravel(direction)]}
    return t, u, setup


def time_response(system, t, u, *, scheme: str = "trapezoidal", rom_method: str = "scheme"):
    """``(y, record)``: :func:`~morsuite.analysis.simulate` of a full or reduced model, and its record
    (``integrator``, ``lu_count``, ``solves``, ``time_s``, ``growth``, ``unstable_poles``,
    ``growth_factor``, ``finite``, ``warnings``; no trajectories)."""
    (y, info), warned = _captured(simulate, system, t, u, scheme=scheme, rom_method=rom_method, details=True)
    keep = ("system", "integrator", "step", "steps", "lu_count", "solves", "time_s", "growth", "unstable_poles",
            "growth_factor", "finite", "constraint_residual")
    return y, {**{k: info.get(k) for k in keep}, "warnings": warned}
