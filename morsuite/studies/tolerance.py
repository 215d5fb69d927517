r"""The tolerance scene's task: one method's search for the smallest model within each tolerance.

:func:`tolerance_search` runs :class:`~morsuite.analysis.tolerance.ToleranceSearch` for one
(model, method, settings) on the full model's band response (the study's full-order response
on the scene's grid, read from the task's argument or the cache: computed once per model and
grid, shared with every method and scene) or on the model's H2 / Hinf norm, and returns plain
data: the search's record (every order evaluated with its error, trust, LUs and time; one
outcome per tolerance) and the reduced models of the chosen and next-smaller orders as ROM
payloads. With ``cache_root`` the result is stored (``kind = "tolerance"``: the models' arrays
in the npz, named ``r{R}__{matrix}``, the record as JSON).

The scene's settings, their validation and the cache key's parts are in
:mod:`morsuite.studies.tol_options` and :func:`morsuite.studies.plan.build_plan`; the table, the
figures and the headline are built by :mod:`morsuite.studies.tolerance_scene`.
"""

from __future__ import annotations

import time
import warnings

from .task_common import CAUGHT, model_of as _model, rom_payload, stamp as _stamp

__all__ = ["tolerance_search", "entry_arrays", "entry_from_cache", "ROM_SEP"]

#: the separator of an npz array's name: ``r{R}__{field}`` (a ROM of order request R)
ROM_SEP = "__"


def _fom_response(fom_result, fom_key, cache_root):
    """(omega, H) of the full-order response: from the task argument, else the cache, else None."""
    if fom_result is not None and "H" in fom_result:
        return fom_result["omega"], fom_result["H"]
    if fom_key is not None and cache_root is not None:
        from .cache import Cache
        hit = Cache(cache_root).get("fom", fom_key)
        if hit is not None:
            return hit[0]["omega"], hit[0]["H"]
    return None


def entry_arrays(entry: dict) -> dict:
    """The npz arrays of a search entry: every kept ROM's matrices as ``r{R}__{field}``."""
    out = {}
    for r, payload in entry.get("roms", {}).items():
        for f, arr in payload["arrays"].items():
            out[f"r{r}{ROM_SEP}{f}"] = arr
    return out


def entry_from_cache(arrays: dict, meta: dict) -> dict:
    """A search entry from its cache entry (:func:`entry_arrays` inverted; the kinds from ``rom_kinds``)."""
    roms = {}
    for name, arr in arrays.items():
        head, _, f = name.partition(ROM_SEP)
        roms.setdefault(int(head[1:]), {})[f] = arr
    kinds = meta.get("rom_kinds", {})
    return {**meta, "roms": {r: {"kind": kinds[str(r)], "arrays": a} for r, a in roms.items()}, "cached": True}


def tolerance_search(source: str, reducer: str, options: dict, settings: dict, norm_options: dict, key: str,
                     fom_result=None, fom_key=None, cache_root=None, run_by: str = "") -> dict:
    """One method's tolerance search (module docstring): a plain-data entry.

    Parameters
    ----------
    source : str
        The model (catalog string or file path).
    reducer, options
        The registered reducer and its options.
    settings : dict
        ``tol`` (list), ``error`` ("band", "h2", "hinf"), ``budget_lus``, ``budget_s``, ``max_states``
        (:func:`morsuite.studies.tol_options.settings`).
    norm_options : dict
        Options of the H2 or Hinf error (the study's ``[norm_options]`` of that kind); {} for "band".
    key : str
        The cache key.
    fom_result : dict, optional
        The full-order response entry (``omega``, ``H``) of a band search; else read from the cache
        (``fom_key``) or computed here.

    Returns
    -------
    dict
        ``search`` (:meth:`~morsuite.analysis.tolerance.ToleranceSearch.record`), ``roms`` (r -> ROM payload
        of every chosen and next-smaller order), ``rom_kinds``, ``time_s``, the stamp; or ``error`` when the
        search could not start (the model or the reducer refused).
    """
    from ..analysis.tolerance import ToleranceSearch

    base = {"kind": "tolerance", "key": key, "reducer": reducer, "cached": False, "scheduler": run_by}
    t0 = time.perf_counter()
    fom = _model(source)
    kw = {}
    if settings["error"] == "band":
        got = _fom_response(fom_result, fom_key, cache_root)
        if got is not None:
            kw = {"omega": got[0], "H_full": got[1]}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # each reduction records its warnings in its info
            search = ToleranceSearch(fom, reducer, options=options, measure=settings["error"],
                                     norm_options={settings["error"]: norm_options} if norm_options else None,
                                     budget_lus=settings.get("budget_lus"), budget_s=settings.get("budget_s"),
                                     max_states=settings.get("max_states"), **kw)
            outcomes = search.run(settings["tol"])
    except CAUGHT as exc:
        return {**base, "error": f"{type(exc).__name__}: {exc}", "time_s": time.perf_counter() - t0, **_stamp()}
    keep = {c.r for o in outcomes for c in (o.chosen, o.smaller) if c is not None and c.rom is not None}
    roms = {r: rom_payload(search.candidates[r].rom) for r in sorted(keep)}
    warned = sorted({w for c in search.candidates.values() for w in c.info.get("warnings", [])})
    out = {**base, "search": search.record(outcomes), "roms": roms,
           "rom_kinds": {str(r): p["kind"] for r, p in roms.items()},
           "infos": {str(r): _info_summary(search.candidates[r].info) for r in sorted(keep)},
           "warnings": warned, "time_s": time.perf_counter() - t0, **_stamp()}
    if cache_root is not None:
        from .cache import Cache
        Cache(cache_root, read=False).put("tolerance", key, entry_arrays(out),
                                          {k: v for k, v in out.items() if k not in ("roms", "cached")})
    return out


#: what a kept model's entry keeps of its reducer's ``info`` (its provenance when it is saved)
_INFO_KEYS = ("method", "model", "r_requested", "r", "states", "kind", "status", "converged", "iterations", "stable",
              "lu_count", "lu_count_shared", "time_s", "lu_backend", "options", "warnings", "continued_from")


def _info_summary(info: dict) -> dict:
    return {k: info.get(k) for k in _INFO_KEYS if k in info}
