r"""Exact error norms in a study: how a study asks for them, their options, and their tasks.

A study computes :math:`\|T - T_r\|_{\mathcal H_2}` and :math:`\|T - T_r\|_{\mathcal H_\infty}`
(:func:`morsuite.analysis.h2_error`, :func:`morsuite.analysis.hinf_error`) only for the
reductions something asks them for:

- the top-level key ``norms = ["h2", "hinf"]``: every reduction of the study (the
  summary gains the columns);
- an ``error_vs_r`` or ``pareto`` scene with ``measure = "h2"``, ``"h2_rel"``,
  ``"hinf"`` or ``"hinf_rel"`` (no grid: these norms cover the whole axis);
- a ``table`` scene with ``norms = ["h2", "hinf"]`` (its rows and the summary's).

Options: ``[norm_options]`` with ``h2 = { rtol = 1e-8, ... }`` and ``hinf = { max_lus = 190, ... }``,
checked against :data:`NORM_OPTIONS` (the keyword options of ``h2_error`` and
``hinf_error``, the same defaults; they live in :mod:`morsuite.studies.norm_options`, which
the spec validates with, and are re-exported here).

Artifacts (cached; keys include the options, the code digest and this file's digest):

- the model's norm per (model, kind, options): :func:`model_norm` (the H2 norm from the
  Gramian factor that ``bt`` shares; the H-infinity norm by the peak search);
- the error norm per (reduction, kind, options): :func:`error_norms` runs one reducer
  group's missing r in one task, so that the model's Gramian factors are computed once.

Relative errors (``h2_rel_error``, ``hinf_rel_error``) divide the two, when the summary is
assembled. The records (route, LUs, floor, trusted flag, warnings) go into the manifest.
"""

from __future__ import annotations

import time
import warnings

from ..linalg.accuracy import recording
from .norm_options import ADI_KEYS, NORM_KINDS, NORM_MEASURES, NORM_OPTIONS, full_options
from .task_common import CAUGHT, model_of as _model, rom_from_payload, stamp as _stamp

__all__ = ["NORM_KINDS", "NORM_OPTIONS", "NORM_MEASURES", "ADI_KEYS", "full_options", "model_norm", "error_norms"]


def model_norm(source: str, kind: str, options: dict, key: str, run_by: str = "", after=None) -> dict:
    r""":math:`\|T\|` of the model in the norm ``kind`` (task; see
    :func:`morsuite.analysis.compare.model_norm`). A failure is recorded as ``error``.
    ``after``: results of tasks that must run first (not used)."""
    from ..analysis.compare import model_norm as compute

    base = {"kind": "model_norm", "norm": kind, "key": key, "cached": False, "scheduler": run_by}
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings(), recording() as solves:
            warnings.simplefilter("ignore")  # recorded in rec["warnings"]
            rec = compute(_model(source), kind, options)
    except CAUGHT as exc:
        return {**base, "error": f"{type(exc).__name__}: {exc}", "time_s": time.perf_counter() - t0, **_stamp()}
    return {**base, **{k: v for k, v in rec.items() if k != "kind"}, **_solves(solves), **_stamp()}


def error_norms(source: str, kind: str, options: dict, rs, keys: dict, run_by: str, *rom_dicts, after=None) -> dict:
    r""":math:`\|T - T_r\|` in the norm ``kind`` for each r (task; see
    :func:`morsuite.analysis.compare.error_norm`). ``rom_dicts`` are the reducer
    group's entries (cached and computed); a failed r is recorded as ``error``.
    ``after``: results of tasks that must run first (not used).

    Cost: the Gramian factors once per model (shared with ``bt`` in this process),
    then per r none to about r LUs (H2, error-Gramian route), 100-1000 (H2, quadrature, rare) or at most
    ``max_lus`` (H-infinity).
    """
    from ..analysis.compare import error_norm

    roms = {}
    for d in rom_dicts:
        roms.update(d or {})
    fom = _model(source)
    out = {}
    for r in rs:
        base = {"kind": "norm_error", "norm": kind, "key": keys[r], "cached": False, "scheduler": run_by}
        entry = roms.get(r)
        if entry is None or "error" in entry:
            out[r] = {**base, "error": "no reduced model" if entry is None else entry["error"], **_stamp()}
            continue
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings(), recording() as solves:
                warnings.simplefilter("ignore")  # recorded in rec["warnings"]
                rec = error_norm(fom, rom_from_payload(entry["rom"]), kind, options)
        except CAUGHT as exc:
            out[r] = {**base, "error": f"{type(exc).__name__}: {exc}", "time_s": time.perf_counter() - t0,
                      **_stamp()}
            continue
        out[r] = {**base, **{k: v for k, v in rec.items() if k != "kind"}, **_solves(solves), **_stamp()}
    return out


def _solves(record) -> dict:
    """What a norm task's own saddle-point solves reached (:mod:`morsuite.linalg.accuracy`; samples kept in
    the model's memo were checked where they were computed: the full response's task)."""
    return {"solve_accuracy": record.as_info(), "solve_backward_error": record.worst}
