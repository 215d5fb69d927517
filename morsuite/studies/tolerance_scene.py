r"""A tolerance scene's outputs: the "to reach" table, its headline, the cost figures, the saved models.

From the searches of :mod:`morsuite.studies.tolerance` (no computing beyond the chosen models'
responses on the scene's grid, dense and cheap):

``NAME`` (table)
    One row per tolerance and method: the status (:data:`~morsuite.analysis.tolerance.OUTCOMES`),
    the states and order of the chosen model, its error (trusted by construction when the status is
    ``met``), the next smaller model's states and error (it misses), the method's LUs and the
    search's time to get there, how many orders were evaluated, and why. Its note is the headline.
``NAME_states`` (figure)
    Every evaluated order's error against its first-order states, one line per method, the
    tolerances drawn, the chosen models starred.
``NAME_time``
    The best error a method had found against the search's time (a staircase: what waiting buys).
``NAME_bode``
    :math:`\sigma_{\max}(T(j\omega))` of the full model and of each method's model chosen for the
    scene's loosest tolerance (band searches; for a norm's tolerance the figure says it has no grid).

:func:`headline` states, per tolerance, the cheapest (least search time) and the smallest (fewest
states) model that meets it, among methods whose status is ``met`` only: a model that does not
meet the tolerance, or an untrusted value, never enters it. :func:`save_roms` writes each chosen
model with its provenance (``save_roms = true``), :func:`tolerance_notes` the run's notes.
"""

from __future__ import annotations

import math

import numpy as np

from ..report.figures import Curve, FigureData
from ..report.tables import TableData

__all__ = ["build_tolerance", "headline", "tolerance_rows", "TOLERANCE_COLUMNS", "save_roms", "tolerance_notes",
           "MEASURE_TEXT"]

#: the columns of the "to reach" table
TOLERANCE_COLUMNS = ["tol", "error_measure", "method", "status", "states", "r", "error", "error_floor", "smaller_states",
                     "smaller_error", "lu_count", "eval_lu_count", "time_s", "evaluated", "reason"]
#: what each error measure is, in words (table notes, figure labels, the headline)
MEASURE_TEXT = {"band": "band max error / band peak", "h2": "H2 error / ||T||_H2",
                "hinf": "Hinf error / ||T||_Hinf (certified upper bound)"}
_YLABEL = {"band": r"$\max_\omega\sigma_{\max}(T - T_r) \,/\, \max_\omega\sigma_{\max}(T)$",
           "h2": r"$\|T - T_r\|_{\mathcal{H}_2} \,/\, \|T\|_{\mathcal{H}_2}$",
           "hinf": r"$\|T - T_r\|_{\mathcal{H}_\infty} \,/\, \|T\|_{\mathcal{H}_\infty}$ (upper bound)"}


#: search times within this factor of the least count as equally cheap in the headline (timing noise)
CHEAP_TIE = 1.2


def _pct(tol: float) -> str:
    return f"{tol * 100:g}%"


def _search(res, scene, m):
    e = res.tolerance(scene.name, m)
    return e, (e or {}).get("search")


def tolerance_rows(scene, study, res) -> list:
    """The "to reach" table's rows (:data:`TOLERANCE_COLUMNS`), tolerances loosest first, methods in scene order."""
    rows = []
    measure = scene.params["error"]
    for tol in scene.params["tol"]:
        for m in scene.methods:
            e, s = _search(res, scene, m)
            row = dict.fromkeys(TOLERANCE_COLUMNS)
            row.update(tol=tol, error_measure=measure, method=m)
            if e is None or s is None:
                row.update(status="failed", reason=(e or {}).get("error") or "not computed")
                rows.append(row)
                continue
            cands = {c["r"]: c for c in s["candidates"]}
            out = next(o for o in s["outcomes"] if math.isclose(o["tol"], tol))
            ch, sm = cands.get(out["chosen"]), cands.get(out["smaller"])
            row.update(status=out["status"], reason=out["reason"], lu_count=out["lus"], eval_lu_count=out["eval_lus"],
                       time_s=out["time_s"],
                       evaluated=sum(1 for c in s["candidates"] if c["cum_time_s"] <= out["time_s"] + 1e-12))
            if ch is not None:
                row.update(states=ch["states"], r=ch["r"], error=ch["value"], error_floor=ch["floor"])
            if sm is not None:
                row.update(smaller_states=sm["states"], smaller_error=sm["value"])
            rows.append(row)
    return rows


def headline(rows, labels=None) -> str:
    """Per tolerance: "within 1% (band ...): cheapest X (N states, L LUs, T s); smallest Y (...)" from the
    rows whose status is ``met``; "no method reached it" (with each method's status) otherwise. ``labels``:
    method alias -> label (default the alias)."""
    labels = labels or {}
    out = []
    for tol in sorted({r["tol"] for r in rows}, reverse=True):
        at = [r for r in rows if r["tol"] == tol]
        measure = MEASURE_TEXT.get(at[0]["error_measure"], at[0]["error_measure"])
        met = [r for r in at if r["status"] == "met"]
        head = f"Within {_pct(tol)} ({measure})"
        if not met:
            out.append(f"{head}: no method reached it ("
                       + ", ".join(f"{labels.get(r['method'], r['method'])}: {r['status']}" for r in at) + ").")
            continue

        def said(r):
            lus = f"{r['lu_count']} LU{'' if r['lu_count'] == 1 else 's'}"
            return f"{labels.get(r['method'], r['method'])} ({r['states']} states, {lus}, {r['time_s']:.3g} s)"
        # times within CHEAP_TIE of the least are as cheap (timing noise): then the fewest LUs decide
        least = min(r["time_s"] for r in met)
        cheapest = min((r for r in met if r["time_s"] <= CHEAP_TIE * least),
                       key=lambda r: (r["lu_count"], r["time_s"], r["states"]))
        fewest = min(r["states"] for r in met)
        smallest = [r for r in met if r["states"] == fewest]  # equal states are equally small: all named
        text = f"{head}: cheapest {said(cheapest)}"
        if smallest == [cheapest]:
            text += "; it is also the smallest"
        elif len(smallest) == 1:
            text += f"; smallest {said(smallest[0])}"
        else:
            text += f"; smallest ({fewest} states): " + ", ".join(said(r) for r in smallest)
        missed = [r for r in at if r["status"] != "met"]
        if missed:
            text += "; not reached by " + ", ".join(f"{labels.get(r['method'], r['method'])} ({r['status']})"
                                                    for r in missed)
        out.append(text + ".")
    return " ".join(out)


def _label(study, m):
    return study.methods[m].label


def _states_figure(scene, study, res, notes):
    measure = scene.params["error"]
    curves = []
    xs = []
    for m in scene.methods:
        e, s = _search(res, scene, m)
        if s is None:
            continue
        pts = sorted((c for c in s["candidates"] if c["value"] is not None and c["error"] is None),
                     key=lambda c: c["states"])
        if not pts:
            continue
        xs += [c["states"] for c in pts]
        curves.append(Curve(m, _label(study, m), {"states": [c["states"] for c in pts],
                                                  "value": [c["value"] for c in pts],
                                                  "trusted": [c["trusted"] for c in pts]}, x="states", style="points"))
        chosen = {o["chosen"] for o in s["outcomes"] if o["status"] == "met"}
        star = [c for c in pts if c["r"] in chosen]
        if star:  # one legend entry for every method's stars
            label = "_chosen" if any(c.style == "chosen" for c in curves) else "chosen: meets it, one order fewer misses"
            curves.append(Curve(f"chosen_{m}", label, {"states": [c["states"] for c in star],
                                                       "value": [c["value"] for c in star]}, x="states", style="chosen"))
    curves += _levels(scene, xs)
    model = study.models[scene.model].name
    return FigureData(f"{scene.name}_states", scene.title or f"{model}: error against states, tolerances dotted",
                      "first-order states of the reduced model", _YLABEL[measure], curves, xscale="log", notes=notes,
                      xplain=True)


def _levels(scene, xs):
    if not xs:
        return []
    lo, hi = min(xs), max(xs)
    return [Curve(f"tol_{i}", f"tolerance {_pct(t)}", {"x": [lo, hi], "value": [t, t]}, x="x", style="level")
            for i, t in enumerate(scene.params["tol"])]


def _time_figure(scene, study, res, notes):
    measure = scene.params["error"]
    curves, xs = [], []
    for m in scene.methods:
        e, s = _search(res, scene, m)
        if s is None:
            continue
        best, t, v = math.inf, [], []
        for c in sorted(s["candidates"], key=lambda c: c["index"]):
            if c["value"] is not None and c["error"] is None and c["stable"]:
                best = min(best, c["value"])
            if math.isfinite(best):
                t.append(max(c["cum_time_s"], 1e-3))
                v.append(best)
        if t:
            xs += t
            curves.append(Curve(m, _label(study, m), {"time_s": t, "value": v}, x="time_s", style="steps"))
    curves += _levels(scene, xs)
    model = study.models[scene.model].name
    return FigureData(f"{scene.name}_time", f"{model}: best error found against search time",
                      "time of the search (s): reductions and error evaluations", _YLABEL[measure], curves,
                      notes=notes)


def _bode_figure(scene, study, res, notes):
    from ..linalg.dense import sigma_max
    from .task_common import rom_from_payload

    model = study.models[scene.model]
    tol = scene.params["tol"][0]
    name = f"{scene.name}_bode"
    title = f"{model.name}: full model and the models chosen for {_pct(tol)}"
    fom = res.fom(scene.model, scene.grid) if scene.grid else None
    if fom is None:
        notes.append(f"scene {scene.name!r}: a {scene.params['error']} tolerance has no grid; no Bode figure drawn")
        return FigureData(name, title, r"$\omega$ (rad/s)", r"$\sigma_{\max}(T(j\omega))$", [], notes=notes)
    omega = fom["omega"]
    curves = [Curve("full", f"full ($n_1 = {model.n1}$)", {"omega": omega, "value": fom["sigma_full"]}, style="full")]
    for m in scene.methods:
        e, s = _search(res, scene, m)
        if s is None:
            continue
        out = next(o for o in s["outcomes"] if math.isclose(o["tol"], tol))
        payload = (e.get("roms") or {}).get(out["chosen"])
        if out["status"] != "met" or payload is None:
            continue
        rom = rom_from_payload(payload)
        curves.append(Curve(m, f"{_label(study, m)} ({rom.states} states)",
                            {"omega": omega, "value": sigma_max(rom.freqresp(omega))}))
    return FigureData(name, title, r"$\omega$ (rad/s)", r"$\sigma_{\max}(T(j\omega))$", curves, notes=notes)


def build_tolerance(scene, study, res) -> list:
    """The scene's table and figures (module docstring), in the order of
    :func:`morsuite.studies.kinds.output_names`."""
    notes = []
    rows = tolerance_rows(scene, study, res)
    labels = {m: _label(study, m) for m in scene.methods}
    note = headline(rows, labels)
    note += (f" Error: {MEASURE_TEXT[scene.params['error']]}; a status other than met says why no model within "
             "the tolerance is given (analysis.tolerance.OUTCOMES); lu_count is the method's sparse LUs in the search "
             "(shared work counted once), eval_lu_count the error evaluations', time_s the search's time (both).")
    title = scene.title or f"{study.models[scene.model].name}: the smallest model within each tolerance"
    table = TableData(scene.name, title, rows, columns=TOLERANCE_COLUMNS,
                      int_columns=("states", "r", "smaller_states", "lu_count", "eval_lu_count", "evaluated"),
                      note=note, notes=notes)
    return [table, _states_figure(scene, study, res, []), _time_figure(scene, study, res, []),
            _bode_figure(scene, study, res, [])]


def tolerance_notes(plan, tolerances) -> list:
    """The run's notes on its tolerance searches: failures, and tolerances not met with the reason."""
    out = []
    for tid, t in plan.tolerances.items():
        e = tolerances.get(tid) or {}
        who = f"tolerance search of {t.method.reducer} on {t.model.name}"
        if "error" in e:
            out.append(f"{who} failed: {e['error']}")
            continue
        for o in (e.get("search") or {}).get("outcomes", []):
            if o["status"] != "met":
                out.append(f"{who}: {_pct(o['tol'])} not met ({o['status']}: {o['reason']})")
    return out


def _slug(x: float) -> str:
    return f"{x:g}".replace(".", "p").replace("-", "m").replace("+", "")


def _errors(measure, cand, search) -> dict:
    """The chosen model's error in the flat names of :func:`morsuite.romfiles.provenance_of`."""
    rec, scale, norm = cand.get("record") or {}, search["scale"], search.get("norm") or {}
    if measure == "band":
        return {"max_abs_error": rec.get("max_abs_error"), "band_peak": scale}  # value = max_abs_error / band_peak
    if measure == "h2":
        return {"h2_error": rec.get("value"), "h2_rel_error": cand["value"], "h2_norm": scale,
                "h2_floor": rec.get("floor"), "h2_trusted": cand["trusted"],
                "h2_norm_floor": norm["floor"] if norm.get("floor") is not None else (norm.get("rel_floor") or 0.0) * scale,
                "h2_route": rec.get("route"), "norm_options": {"h2": norm.get("options")}}
    return {"hinf_error": rec.get("lower_bound", rec.get("value")), "hinf_upper_bound": rec.get("upper_bound"),
            "hinf_certified": bool(rec.get("certified")), "hinf_rel_error": cand["value"], "hinf_norm": scale,
            "hinf_norm_upper_bound": norm.get("upper_bound"), "hinf_peak_frequency": rec.get("peak_frequency"),
            "norm_options": {"hinf": norm.get("options")}}


def save_roms(study, res, outdir) -> list:
    """Write each chosen model of the tolerance scenes with ``save_roms = true`` into ``outdir/roms/`` as
    ``SCENE_METHOD_tolTOL.npz``, ``.mat`` and ``.json`` (:func:`morsuite.romfiles.save_rom`; provenance by
    :func:`morsuite.romfiles.provenance_of`, so that ``morsuite verify`` recomputes its errors); returns the
    paths written. Cost: building the model in this process (its hash) once per scene."""
    from pathlib import Path

    from .task_common import model_of, rom_from_payload

    paths = []
    for scene in study.scenes:
        if scene.kind != "tolerance" or not scene.params.get("save_roms"):
            continue
        from ..romfiles import provenance_of, save_rom
        model, measure = study.models[scene.model], scene.params["error"]
        fom = model_of(model.source)
        fom_entry = res.fom(scene.model, scene.grid) if scene.grid else None
        grid = None if fom_entry is None else (float(fom_entry["omega"][0]), float(fom_entry["omega"][-1]),
                                               int(np.size(fom_entry["omega"])))
        for m in scene.methods:
            e, s = _search(res, scene, m)
            if s is None:
                continue
            cands = {c["r"]: c for c in s["candidates"]}
            for o in s["outcomes"]:
                payload = (e.get("roms") or {}).get(o["chosen"])
                if o["status"] != "met" or payload is None:
                    continue
                c, method = cands[o["chosen"]], study.methods[m]
                prov = provenance_of(fom, method.reducer, method.options, (e.get("infos") or {}).get(str(o["chosen"]), {}),
                                     errors=_errors(measure, c, s), band=grid[:2] if grid else None, grid=grid,
                                     source=model.spec, cost={"search_lu_count": o["lus"], "search_time_s": o["time_s"]},
                                     extra={"tolerance": {"tol": o["tol"], "measure": measure, "status": o["status"],
                                                          "reason": o["reason"], "value": c["value"],
                                                          "floor": c["floor"], "trusted": c["trusted"]},
                                            "study": study.name, "scene": scene.name, "alias": m})
                stem = Path(outdir) / "roms" / f"{scene.name}_{m}_tol{_slug(o['tol'])}"
                paths += save_rom(rom_from_payload(payload), stem, provenance=prov)
    return paths
