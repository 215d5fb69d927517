r"""The ``modes`` scene: does each reduced model keep the structure's modes and physics?

For a scene of kind ``modes`` (model, grid, methods, one r per method) the driver computes,
once per run and before the outputs are drawn:

- the full model's poles in and near the grid's band, with damping ratios and mode shapes
  (:func:`morsuite.analysis.modes.model_modes`: shift-invert Arnoldi on a few saddle LUs);
- per reduced model, its poles (:func:`~morsuite.analysis.modes.rom_modes`), matched to the
  full model's in the band (:func:`~morsuite.analysis.modes.match_modes`: relative frequency
  error, damping error, missing and spurious modes), the MAC of each matched pair where the
  model has a lift :math:`V` (``rom.basis``: the full mode shape against :math:`Vq`;
  ``None``, shown as "no lift", otherwise), and the structure checks
  (:func:`~morsuite.analysis.modes.structure_checks`: :math:`\hat M, \hat K` symmetric positive
  definite, :math:`\hat D` semidefinite, stable), with the summary's ``worse_than_zero`` (the
  norms in which the model is no better than :math:`T_r = 0`).

The result is plain data in the page's format (``docs/design/reports.md``, "Modes and poles"):
``rows`` (one per full mode in the band and method, plus the spurious ones), ``poles`` (the full
model's, then each reduced model's), ``structure`` (one row per method) and ``note``. The scene's
tables (``NAME.csv``: the rows; ``NAME_structure.csv``: the checks) are written from it, so the
page and the CSV files show the same numbers.

Cost: the full model's modes (a few LUs; ``info["lu_count"]``), then dense work of order 2r per
reduced model and O(n1 k) per MAC.
"""

from __future__ import annotations

import math
import time
import warnings

import numpy as np

from ..errors import ConvergenceWarning

__all__ = ["MAX_MODES", "MODES_MAXITER", "MODES_TOL", "GLANCE_MAC", "MODES_COLUMNS", "STRUCTURE_COLUMNS", "compute_modes",
           "modes_key"]

#: the full model's modes a table shows: those some reduced model matches, then the lowest others, at most
#: this many; also the cap of the poles computed per shift (``max_poles`` of
#: :func:`~morsuite.linalg.poles.damped_poles`): a lightly damped model has hundreds in its band
#: (406 on the DSMS g = 600, 80 s), and a report needs the dominant few at a few percent of its time.
#: The Arnoldi asks for this many from the start (``k``): a first run at 10 and a rerun at the cap cost
#: 3301 solves for 10 poles on the DSMS g = 600, one run at 24 cost 1966 for 24 (2.0-2.4x faster; tcom(2000)
#: 1.7x; fem_block(4000) 0.86x; one run, load 7, 2026-11-27)
MAX_MODES = 24
#: ARPACK's relative accuracy of the full model's poles in a report (``tol`` of
#: :func:`~morsuite.linalg.poles.damped_poles`; its default 0, machine precision, took 3x the solves on the
#: clustered spectrum of the DSMS g = 600, 2026-11-27): frequencies to about 1e-9, residuals are reported
MODES_TOL = 1e-9
#: ARPACK's restarts per run in a report (``maxiter`` of :func:`~morsuite.linalg.poles.damped_poles`): the
#: DSMS g = 6000 took 84,000 solves (138 s, loaded machine) for 3 poles in its band without a cap; a pole
#: not converged within it is left out and the note says the list may be incomplete
MODES_MAXITER = 30

#: columns of the modes table (and of the page's rows)
MODES_COLUMNS = ["model", "method", "r", "mode", "status", "full_frequency", "reduced_frequency",
                 "rel_frequency_error", "full_damping", "damping_error", "mac"]
#: the MAC at or above which a matched mode counts as kept in shape (``mac_kept`` of the structure table and
#: the page's line at a glance under the scoreboard); a common acceptance level in test-analysis correlation
GLANCE_MAC = 0.9
#: columns of the structure table
STRUCTURE_COLUMNS = ["model", "method", "r", "kind", "symmetric", "M_spd", "K_spd", "D_psd", "stable",
                     "lift", "matched", "missing", "spurious", "mac_kept", "worse_than_zero"]


def _num(x):
    x = float(x)
    return None if not math.isfinite(x) else x


def _pole_list(label, result):
    return {"label": label, "real": [float(v) for v in result.poles.real],
            "imag": [float(v) for v in result.poles.imag]}


def modes_key(scene, study, res) -> str | None:
    """The cache key of a ``modes`` scene's data: the model, the band, the scene's methods with the cache
    keys of their reductions (a new reduced model is a new key) and their ``worse_than_zero`` flags, the
    report's eigensolver settings, the
    numerical code (:func:`~morsuite.studies.cache.cache_key`) and this module's source. None when a
    reduction has no key (then nothing is cached)."""
    from .cache import cache_key, source_digest

    entry = study.models[scene.model]
    reds = []
    for method in scene.methods:
        r = scene.rs_of(method)[0]
        red = res.reduction(scene.model, method, r) or {}
        if "error" not in red and not red.get("key"):
            return None
        zero = res.summary_row(scene.model, method, r, scene.grid).get("worse_than_zero")
        reds.append([method, int(r), red.get("key"), red.get("error"), zero])
    grid = study.grids[scene.grid]
    return cache_key("modes", model=str(entry.source), band=list(grid.bounds_for(entry)[:2]), reductions=reds,
                     settings=[MAX_MODES, MODES_TOL, MODES_MAXITER, GLANCE_MAC],
                     source=source_digest("studies/modes.py"))


def compute_modes(scene, study, res) -> dict:
    """The modes, MAC and structure checks of ``scene`` (kind ``modes``) from the run's results ``res``.

    Parameters
    ----------
    scene : SceneEntry
        Its ``model``, ``grid`` (the band), ``methods`` and their orders (``rs_of``).
    study : Study
    res : Results
        The reductions of the run (their ROM payloads; a ROM saved with its lift keeps it).

    Returns
    -------
    dict
        ``rows``, ``poles``, ``structure``, ``note`` and ``info`` (the full model's solve: LUs,
        shifts, time). Plain data.
    """
    from ..analysis.modes import mac, match_modes, model_modes, rom_modes, structure_checks
    from .task_common import model_of, rom_from_payload

    entry = study.models[scene.model]
    fom = model_of(entry.source)
    grid = study.grids[scene.grid]
    lo, hi, _ = grid.bounds_for(entry)
    band = (float(lo), float(hi))
    t0 = time.perf_counter()
    with warnings.catch_warnings():  # the eigensolver's budget warnings: said once, in the note (covered)
        warnings.simplefilter("ignore", ConvergenceWarning)
        full = model_modes(fom, band, k=MAX_MODES, max_poles=MAX_MODES, tol=MODES_TOL, maxiter=MODES_MAXITER)
    t_full = time.perf_counter() - t0
    in_band = np.flatnonzero(full.in_band)
    rows, poles, structure, notes = [], [_pole_list("full", full)], [], []
    matched = {}
    for method in scene.methods:
        r = scene.rs_of(method)[0]
        red = res.reduction(scene.model, method, r)
        if red is None or "error" in red:
            notes.append(f"{method} r = {r}: no reduced model ({(red or {}).get('error', 'not computed')})")
            continue
        rom = rom_from_payload(red["rom"])
        rm = rom_modes(rom, band)
        df = match_modes(full, rm, band)
        lift = rm.shapes is not None
        matched[method] = df
        for rec in df.to_dict("records"):
            i, k = int(rec["full_index"]), int(rec["rom_index"])
            value = None
            if lift and rec["status"] == "matched":
                value = float(mac(full.shapes[:, i], rm.shapes[:, k])[0, 0])
            rows.append({"model": scene.model, "method": method, "r": int(r),
                         "mode": int(np.searchsorted(in_band, i)) + 1 if i >= 0 else None,
                         "status": rec["status"], "full_frequency": _num(rec["freq_full"]),
                         "reduced_frequency": _num(rec["freq_rom"]),
                         "rel_frequency_error": _num(rec["rel_freq_error"]),
                         "full_damping": _num(rec["damping_full"]), "damping_error": _num(rec["damping_error"]),
                         "mac": value})
        checks = structure_checks(rom)
        counts = df["status"].value_counts()
        macs = [row["mac"] for row in rows if row["method"] == method and row["mac"] is not None]
        zero = res.summary_row(scene.model, method, r, scene.grid).get("worse_than_zero")
        structure.append({"model": scene.model, "method": method, "r": int(r), "kind": rom.kind,
                          **{k: checks.get(k) for k in ("symmetric", "M_spd", "K_spd", "D_psd", "stable")},
                          "lift": lift, **{k: int(counts.get(k, 0)) for k in ("matched", "missing", "spurious")},
                          "mac_kept": sum(1 for v in macs if v >= GLANCE_MAC) if lift else None,
                          "worse_than_zero": zero or ""})
        poles.append(_pole_list(f"{method} r = {r}", rm))
    shown = _shown_modes(matched, in_band)
    rows = [row for row in rows if row["mode"] is None or row["mode"] in shown]
    if in_band.size > len(shown):
        notes.append(f"the table shows {len(shown)} of the {in_band.size} modes in the band (those a reduced model "
                     "matches, then the lowest); the structure table counts all")
    nolift = [s["method"] for s in structure if not s["lift"]]
    if nolift:
        notes.append("no lift V (no MAC): " + ", ".join(nolift))
    if not full.info.get("covered", True):
        budget = (f"{MAX_MODES} modes per decade of the band" if full.info.get("method") == "proportional"
                  else f"{MAX_MODES} poles per shift and {MODES_MAXITER} restarts")
        notes.append(f"the full model's list may miss modes in the band (the eigensolver's budget, {budget}, "
                     "was reached)")
    info = {"band": list(band), "modes_in_band": int(in_band.size), "time_s": t_full, "glance_mac": GLANCE_MAC,
            **{k: full.info.get(k) for k in ("lu_count", "shifts", "covered", "max_residual", "method")}}
    how = ("from the undamped modes under Rayleigh damping, the lowest from the band's lower edge up"
           if full.info.get("method") == "proportional"
           else f"at most {MAX_MODES} per shift, nearest each")
    note = (f"The full model's {in_band.size} modes found in [{band[0]:.3g}, {band[1]:.3g}] rad/s "
            f"({how}) "
            f"({info['lu_count']} LU{'' if info['lu_count'] == 1 else 's'}, {t_full:.2f} s). " + "; ".join(notes))
    return {"rows": rows, "poles": poles, "structure": structure, "note": note.strip(), "info": info}


def _shown_modes(matched, in_band) -> set:
    """Mode numbers (1-based, in the band) the table shows: every mode some reduced model matches, then
    the lowest others, :data:`MAX_MODES` in all (all matched ones even beyond)."""
    hit = set()
    for df in matched.values():
        idx = df.loc[df["status"] == "matched", "full_index"].to_numpy(dtype=int)
        hit |= {int(np.searchsorted(in_band, i)) + 1 for i in idx}
    rest = [k for k in range(1, in_band.size + 1) if k not in hit]
    return hit | set(rest[: max(0, MAX_MODES - len(hit))])
