"""The tasks of a study's graph: pure functions of plain data, run by any Dask scheduler.

Each task builds what it needs from plain arguments (the model from its catalog
string or file path), measures its own time with ``time.perf_counter`` and returns
plain data: arrays, numbers, strings, dicts. A reduced model travels as
``{"kind": ..., "arrays": {name: ndarray}}``, never as a pickled object on disk.

- :func:`fom_response`: the full model's response on one grid (one LU per
  frequency), shared by every reduced model compared on that grid, and kept in the
  model's memo of T(jw) for the H-infinity searches (:func:`~morsuite.analysis.response.band_response`).
- :func:`reduce_sweep`: one reducer instance for one (model, method, options),
  ``reduce(r)`` for every requested r in increasing order, so work that does not
  depend on r (Gramian factors, a projector) is done once.
- :func:`metrics`: reduced responses and errors on a grid for the ROMs of one
  (model, method, options).

Exact norms and time-domain simulations are the tasks of :mod:`morsuite.studies.norms` and
:mod:`morsuite.studies.timedomain`; what the three share (the model built once per
process, the ROM payload, the failures recorded) is :mod:`morsuite.studies.task_common`.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from .task_common import CAUGHT, model_of as _model, rom_from_payload, rom_payload, stamp as _stamp

__all__ = ["FOM_ARRAYS", "fom_response", "reduce_sweep", "metrics", "rom_payload", "rom_from_payload", "CAUGHT"]

# ``_model`` and ``_stamp`` are kept under their old names here (tests clear ``tasks._model``'s
# cache); they live in :mod:`.task_common`, which the norm and time-domain tasks import too.


#: The arrays of a full-order response entry (stored as npz; the rest as JSON).
FOM_ARRAYS = ("omega", "H", "sigma_full")


def fom_response(source: str, lo: float, hi: float, n: int, key: str, cache_root=None, progress=False,
                 run_by: str = "") -> dict:
    r"""Full-order response ``H`` on ``n`` log-spaced frequencies ``omega`` in [lo, hi] (rad/s),
    and ``sigma_full`` = :math:`\sigma_{\max}(H(j\omega))` (kept with it: a cached study then
    needs no linear algebra); ``solve_accuracy`` and ``solve_backward_error``, what its solves
    reached (:mod:`morsuite.linalg.accuracy`)."""
    from ..analysis import sigma_max
    from ..analysis.response import band_response
    from ..linalg.accuracy import recording
    from ..utils import default_threads

    fom = _model(source)
    omega = np.logspace(np.log10(lo), np.log10(hi), n)
    t0 = time.perf_counter()
    # through the model's memo of T(jw): the H-infinity searches with this band grid draw on it; the
    # frequencies on the solver threads IRKA's shift solves use (the values do not depend on them)
    threads = default_threads(fom.solver.backend)
    with recording() as solves:
        H, lus = band_response(fom, omega, progress=progress, threads=threads)
    elapsed = time.perf_counter() - t0
    out = {"kind": "fom", "key": key, "model": fom.name, "omega": omega, "H": H, "sigma_full": sigma_max(H),
           "time_s": elapsed, "lu_count": lus, "solver_threads": threads, "cached": False, "scheduler": run_by,
           "solve_accuracy": solves.as_info(), "solve_backward_error": solves.worst, **_stamp()}
    if cache_root is not None:
        from .cache import Cache
        Cache(cache_root, read=False).put("fom", key, {k: out[k] for k in FOM_ARRAYS},
                                          {k: v for k, v in out.items() if k not in FOM_ARRAYS + ("cached",)})
    return out


def reduce_sweep(source: str, reducer: str, options: dict, rs, keys: dict, cache_root=None,
                 run_by: str = "") -> dict:
    """``reduce(r)`` for each r in increasing order on ONE reducer instance.

    Returns ``{r: entry}``; an entry holds the ROM payload, the reducer's ``info``,
    ``time_s`` (the reducer's own timing of this call), ``time_standalone_s``
    and ``lu_count_standalone`` (:func:`~morsuite.reducers.outcome.standalone_time`,
    :func:`~morsuite.reducers.outcome.standalone_lu_count`), ``wall_s`` (this task's timing of the call), ``call_index`` (0 for the call that did the r-independent
    work) or, for a failed r, ``error``. With ``cache_root`` each entry is stored
    as soon as it exists, so an interrupted sweep resumes where it stopped.
    """
    from .. import reducers
    from ..reducers.outcome import standalone_lu_count, standalone_time
    from .cache import Cache

    cache = Cache(cache_root, read=False) if cache_root is not None else None
    fom = _model(source)
    t0 = time.perf_counter()
    red = reducers.make(reducer, fom, **options)
    t_make = time.perf_counter() - t0
    out = {}
    for i, r in enumerate(sorted(rs)):
        base = {"kind": "reduction", "key": keys[r], "r_requested": int(r), "reducer": reducer,
                "call_index": i, "construct_s": t_make if i == 0 else 0.0, "cached": False, "scheduler": run_by}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # each reducer records its warnings in info["warnings"]
            t1 = time.perf_counter()
            try:
                res = red.reduce(int(r))
            except CAUGHT as exc:
                out[r] = {**base, "error": f"{type(exc).__name__}: {exc}",
                          "wall_s": time.perf_counter() - t1, **_stamp()}
                continue
            wall = time.perf_counter() - t1
        info = res.info
        entry = {**base, "rom": rom_payload(res.rom), "info": info, "time_s": float(info.get("time_s", wall)),
                 "time_standalone_s": standalone_time(info, wall), "lu_count_standalone": standalone_lu_count(info),
                 "wall_s": wall, **_stamp()}
        if cache is not None:
            cache.put("reduction", keys[r], entry["rom"]["arrays"],
                      {**{k: v for k, v in entry.items() if k not in ("rom", "cached")},
                       "rom_kind": entry["rom"]["kind"]})
        out[r] = entry
    return out


def metrics(fom_result: dict, rs, *rom_dicts) -> dict:
    r"""Errors of the ROMs ``rs`` (looked up in ``rom_dicts``) on the full model's grid.

    For each r: ``sigma_rom``, ``abs_error`` (:math:`\sigma_{\max}(T - T_r)`),
    ``rel_error`` (divided by :math:`\sigma_{\max}(T)`) and their maxima over the grid,
    ``max_abs_error`` and ``max_rel_error``: band quantities. Norms over the whole axis
    are the tasks of :mod:`morsuite.studies.norms`.
    """
    from ..analysis import errors

    roms = {}
    for d in rom_dicts:
        roms.update(d or {})
    omega, H = fom_result["omega"], fom_result["H"]
    out = {}
    for r in rs:
        entry = roms.get(r)
        if entry is None or "error" in entry:
            out[r] = {"error": "no reduced model" if entry is None else entry["error"]}
            continue
        t0 = time.perf_counter()
        rom = rom_from_payload(entry["rom"])
        df = errors(None, rom, omega, H_full=H)
        out[r] = {"sigma_rom": df["sigma_rom"].to_numpy(), "abs_error": df["abs_error"].to_numpy(),
                  "rel_error": df["rel_error"].to_numpy(), "max_abs_error": float(df["abs_error"].max()),
                  "max_rel_error": float(df["rel_error"].max()), "time_s": time.perf_counter() - t0}
    return out
