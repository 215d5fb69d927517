r"""Scene kinds: what each figure or table needs, and how it is built from results.

The kinds' table, :func:`needs` and :func:`output_names` live in :mod:`morsuite.studies.kinds`
(the spec and the plan read them there) and are re-exported here; this module builds
each scene's figures and tables from the results.

A scene names one model, one or more methods (aliases of the study's
``[methods]``), the reduced orders ``r`` and, for frequency-domain scenes, a grid.

============ ======================================================== ===== =====
kind         shows                                                    grid  r
============ ======================================================== ===== =====
sigma        :math:`\sigma_{\max}(T(j\omega))` of full and reduced    yes   one
error        absolute (``error = "abs"``) or relative error           yes   one
compare      error of several methods at one r (BT vs IRKA)           yes   one
error_vs_r   an error measure against r (see ``measure``)             [1]   many
time_vs_r    reduction time against r                                 no    many
pareto       time against an error measure, one point per (method, r) [1]   many
convergence  IRKA's shift change per iteration, one curve per r       no    many
hsv          Hankel singular values (methods that report ``hsv``)     no    one
table        table of the scene's reductions (``norms = [...]``)      yes   many
time         :math:`y` and :math:`y_r` over time, and their error     no    one
============ ======================================================== ===== =====

[1] ``measure``: ``"max_abs"`` / ``"max_rel"`` (the band maximum of
:math:`\sigma_{\max}(T - T_r)`, absolute or over :math:`\sigma_{\max}(T)`, on the
scene's grid) or ``"h2"``, ``"h2_rel"``, ``"hinf"``, ``"hinf_rel"`` (exact norms over
the whole axis, :mod:`morsuite.studies.norms`; no grid). The band-limited trapezoidal
``h2_error_grid`` of earlier versions is gone: the exact H2 error replaced the one
scene that used it.

A ``time`` scene (:mod:`morsuite.studies.timedomain`) makes two figures, ``NAME``
(:math:`y` of the full model and :math:`y_r` of each method, one output channel) and
``NAME_error`` (:math:`\|y(t) - y_r(t)\|_2`), each curve thinned to at most
:data:`MAX_POINTS` samples (the minimum and maximum of each stretch: peaks stay).

``needs(scene)`` lists the artifacts a scene uses, so a study computes nothing
that no scene shows: scenes without a grid never trigger a full-order response,
norms are computed only for the reductions that a measure, a table or the study's
``norms`` key names, and a method appears only when a scene names it.

Curves against r use the x column ``r`` (the order of the reduced model, from
``info["r"]``) or ``states`` (first-order states: 2r for a second-order ROM), as
the scene's ``axis`` says; the CSV files carry both and ``r_requested``. A
``pareto`` scene writes the same quantity beside each point. First-order and
second-order ROMs meet on the states axis: ``r_by_method = { fo = { from = 4, to = 80,
step = 4 } }`` gives a method orders of its own (every scene kind; one per method in
the kinds that show one r), so that a first-order reducer runs at 2r states beside
second-order ones at r. A table whose methods differ in the states per order
compares them in its verdict at equal requested states; within that, its verdict ranks only
rows of equal states and values above their floors (:mod:`morsuite.report.ranking`).

A scene's curves are plain columns (name -> values), no DataFrames: building a
scene is cheap and imports neither pandas nor matplotlib, so that a study can key
each figure by its data and skip the ones that did not change.
"""

from __future__ import annotations

import csv

import numpy as np

from ..report.figures import Curve, CsvSource, FigureData
from ..report.ranking import excluded_text, rank
from ..report.tables import TableData
from .kinds import AXES, COMMON_KEYS, KINDS, MAX_POINTS, MEASURES, TIMES, Kind, needs, orders_text, output_names
from .norm_options import NORM_MEASURES
from .time_figures import time_figures
from .tolerance_scene import build_tolerance

__all__ = ["KINDS", "COMMON_KEYS", "Kind", "TableData", "needs", "build", "output_names", "MEASURES", "AXES",
           "TIMES", "MAX_POINTS", "order_groups"]

_orders_text = orders_text  # its old name here

OMEGA = r"$\omega$ (rad/s)"
YLABEL = {
    "sigma": r"$\sigma_{\max}(T(j\omega))$",
    "abs": r"$\sigma_{\max}(T(j\omega) - T_r(j\omega))$",
    "rel": r"$\sigma_{\max}(T - T_r) \,/\, \sigma_{\max}(T)$",
    "max_abs": r"$\max_\omega \sigma_{\max}(T - T_r)$ on the grid",
    "max_rel": r"$\max_\omega \sigma_{\max}(T - T_r)/\sigma_{\max}(T)$ on the grid",
    "h2": r"$\|T - T_r\|_{\mathcal{H}_2}$",
    "h2_rel": r"$\|T - T_r\|_{\mathcal{H}_2} \,/\, \|T\|_{\mathcal{H}_2}$",
    "hinf": r"$\|T - T_r\|_{\mathcal{H}_\infty}$, peak found (lower bound)",
    "hinf_rel": r"$\|T - T_r\|_{\mathcal{H}_\infty} \,/\, \|T\|_{\mathcal{H}_\infty}$, peaks found",
}
MEASURE_COLUMN = {"max_abs": "max_abs_error", "max_rel": "max_rel_error", "h2": "h2_error", "h2_rel": "h2_rel_error",
                  "hinf": "hinf_error", "hinf_rel": "hinf_rel_error"}
XLABEL = {"r": r"reduced order $r$", "states": r"first-order states of the ROM ($2r$ for second order)"}
TIME_LABEL = {"standalone": "time (s), reduction at this r alone",
              "call": "time (s) of reduce(r), shared work reused"}


# -- building --------------------------------------------------------------
def _columns(records):
    """List of dicts (same keys) -> dict of columns, in the first record's key order."""
    return {k: [rec[k] for rec in records] for k in records[0]}


def _check_csv(path):
    """Why ``path`` is not a CSV table with a header (None if it is): the cases in
    which pandas would refuse it, found without parsing numbers."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = csv.reader(fh)
            header = next(rows, None)
            if not header:
                return "no columns to parse from file"
            for i, row in enumerate(rows, start=2):
                if len(row) > len(header):
                    return f"expected {len(header)} fields in line {i}, saw {len(row)}"
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        return str(exc)
    return None


def _paper_curves(scene, study, x, notes):
    out = []
    for curve, path in scene.paper.items():
        if not path.is_file():
            notes.append(f"scene {scene.name!r}: paper curve {str(path)!r} not found; overlay skipped")
            continue
        bad = _check_csv(path)
        if bad is not None:
            notes.append(f"scene {scene.name!r}: paper curve {str(path)!r} unreadable ({bad}); overlay skipped")
            continue
        data = CsvSource(path, x)  # parsed only if the figure is drawn
        if data.columns != [x, "value"]:
            notes.append(f"scene {scene.name!r}: paper curve {str(path)!r} lacks columns (x, value); skipped")
            continue
        label = "full" if curve == "full" else study.methods[curve].label
        out.append(Curve(name=f"paper_{curve}", label=f"paper ({label})", data=data, x=x, style="paper"))
    return out


def _title(scene, study, default):
    return scene.title or default


def _missing(notes, scene, method, r, what):
    notes.append(f"scene {scene.name!r}: {method} at r = {r}: {what}; not shown")


def _freq_scene(scene, study, res):
    notes = []
    model = study.models[scene.model]
    r = scene.rs[0]
    at = _orders_text(scene)
    fom = res.fom(scene.model, scene.grid)
    omega = fom["omega"]
    curves = []
    if scene.kind == "sigma":
        curves.append(Curve("full", f"full ($n_1 = {model.n1}$)", {"omega": omega, "value": fom["sigma_full"]},
                            style="full"))
        ylabel, col = YLABEL["sigma"], "sigma_rom"
        default = f"{model.name}: full and reduced models at {at}"
    else:
        err = scene.params["error"]
        ylabel, col = YLABEL[err], f"{err}_error"
        default = f"{model.name}: {'absolute' if err == 'abs' else 'relative'} error at {at}"
    for m in scene.methods:
        r = scene.rs_of(m)[0]
        met = res.metrics(scene.model, scene.grid, m, r)
        if met is None or "error" in met:
            _missing(notes, scene, m, r, met["error"] if met else "not computed")
            continue
        red = res.reduction(scene.model, m, r)
        got = int(red["info"]["r"])
        label = f"{study.methods[m].label} ($r = {got}$" + (f", {r} requested)" if got != r else ")")
        curves.append(Curve(m, label, {"omega": omega, "value": met[col]}))
    curves += _paper_curves(scene, study, "omega", notes)
    return FigureData(scene.name, _title(scene, study, default), OMEGA, ylabel, curves, notes=notes)


def _r_rows(scene, study, res, m):
    """``(r, (reduction entry, values), None)`` for each r of the scene that succeeded, else
    ``(r, None, why)``; ``values``: the metrics on the scene's grid and, for a norm measure,
    the norm columns (:meth:`~morsuite.studies.results.Results.norm_columns`)."""
    rows = []
    measure = scene.params.get("measure")
    for r in scene.rs_of(m):
        red = res.reduction(scene.model, m, r)
        if red is None or "error" in red:
            rows.append((r, None, red["error"] if red else "not computed"))
            continue
        met = res.metrics(scene.model, scene.grid, m, r) if scene.grid else None
        if met is not None and "error" in met:
            rows.append((r, None, met["error"]))
            continue
        values = dict(met or {})
        if measure in NORM_MEASURES:
            values.update(res.norm_columns(scene.model, m, r))
            if values.get(MEASURE_COLUMN[measure]) is None:
                rows.append((r, None, values.get(f"{NORM_MEASURES[measure][0]}_failed") or "not computed"))
                continue
        rows.append((r, (red, values), None))
    return rows


def _hinf_flag(best, second) -> str:
    """What an Hinf ranking rests on: peaks found are lower bounds; certified when the winner's upper
    bound is below the next one's lower bound."""
    up = best.get("hinf_upper_bound")
    if best.get("hinf_certified") and up is not None and up < second["hinf_error"]:
        return " (peaks found, lower bounds; the order is certified by the upper bounds)"
    return " (peaks found, lower bounds; the order is not certified)"


def _trust(values, measure, notes, scene, m, r):
    """The trusted flag of a norm measure's value (None for band measures); untrusted ones get a note."""
    if measure not in NORM_MEASURES:
        return {}
    ok = values.get(f"{NORM_MEASURES[measure][0]}_trusted")
    if ok is False:
        notes.append(f"scene {scene.name!r}: {m} at r = {r}: the {MEASURE_COLUMN[measure]} value is not accurate "
                     "to four digits (trusted = False in its CSV)")
    return {"trusted": ok}


def _flagged(m, study, recs, x, y) -> list:
    """A ring around each point whose norm is not accurate to four digits (``trusted`` False)."""
    bad = [rec for rec in recs if rec.get("trusted") is False]
    if not bad:
        return []
    return [Curve(f"flagged_{m}", f"{study.methods[m].label}: not accurate to 4 digits",
                  {x: [rec[x] for rec in bad], y: [rec[y] for rec in bad]}, x=x, style="flagged")]


def _r_frame(red, x_extra):
    info = red["info"]
    return {"r": int(info["r"]), "states": int(info["states"]), "r_requested": int(red["r_requested"]),
            "cached": bool(red.get("cached", False)), **x_extra}


def _against_r_scene(scene, study, res):
    notes = []
    model = study.models[scene.model]
    axis = scene.params["axis"]
    curves = []
    if scene.kind == "error_vs_r":
        measure = scene.params["measure"]
        ylabel = YLABEL[measure]
        default = f"{model.name}: {MEASURE_COLUMN[measure].replace('_', ' ')} against {axis}"
    else:
        tmode = scene.params["time"]
        ylabel = TIME_LABEL[tmode]
        default = f"{model.name}: reduction time against {axis}"
    for m in scene.methods:
        recs = []
        for r, pair, err in _r_rows(scene, study, res, m):
            if pair is None:
                _missing(notes, scene, m, r, err)
                continue
            red, met = pair
            extra = {}
            if scene.kind == "error_vs_r":
                value = met[MEASURE_COLUMN[measure]]
                extra = _trust(met, measure, notes, scene, m, r)
            else:
                value = red["time_standalone_s"] if tmode == "standalone" else red["time_s"]
            recs.append(_r_frame(red, {"value": value, **extra}))
        if recs:
            cols = _columns(recs)
            cols = {k: cols[k] for k in [axis, "value"] + [c for c in cols if c not in (axis, "value")]}
            curves.append(Curve(m, study.methods[m].label, cols, x=axis, style="points"))
            curves += _flagged(m, study, recs, axis, "value")
    curves += _paper_curves(scene, study, axis, notes)
    return FigureData(scene.name, _title(scene, study, default), XLABEL[axis], ylabel, curves,
                      xscale="linear", notes=notes)


def _pareto_scene(scene, study, res):
    notes = []
    model = study.models[scene.model]
    measure, tmode, axis = scene.params["measure"], scene.params["time"], scene.params["axis"]
    col = MEASURE_COLUMN[measure]
    curves = []
    for m in scene.methods:
        recs = []
        for r, pair, err in _r_rows(scene, study, res, m):
            if pair is None:
                _missing(notes, scene, m, r, err)
                continue
            red, met = pair
            t = red["time_standalone_s"] if tmode == "standalone" else red["time_s"]
            recs.append({col: met[col], "value": t, **_r_frame(red, _trust(met, measure, notes, scene, m, r))})
        if recs:
            curves.append(Curve(m, study.methods[m].label, _columns(recs), x=col, style="points",
                                annotate=axis))
            curves += _flagged(m, study, recs, col, "value")
    per = "r" if axis == "r" else "order (first-order states written beside each point)"
    return FigureData(scene.name, _title(scene, study, f"{model.name}: time against error, one point per {per}"),
                      YLABEL[measure], TIME_LABEL[tmode], curves, notes=notes)


def _convergence_scene(scene, study, res):
    notes = []
    model = study.models[scene.model]
    curves = []
    for m in scene.methods:
        for r, pair, err in _r_rows(scene, study, res, m):
            if pair is None:
                _missing(notes, scene, m, r, err)
                continue
            hist = (pair[0]["info"].get("history") or {}).get("measure")
            if not hist:
                _missing(notes, scene, m, r, "no convergence history (info['history']['measure'])")
                continue
            df = {"iteration": np.arange(1, len(hist) + 1), "value": np.asarray(hist, float)}
            info = pair[0]["info"]
            conv = info.get("status") or ("converged" if info.get("converged") else "not converged")
            curves.append(Curve(f"{m}_r{r}", f"{study.methods[m].label}, $r = {r}$ ({conv})", df, x="iteration"))
    return FigureData(scene.name, _title(scene, study, f"{model.name}: IRKA convergence"), "iteration",
                      "convergence measure (relative change of shifts or response)", curves, xscale="linear",
                      notes=notes)


def _hsv_scene(scene, study, res):
    notes = []
    model = study.models[scene.model]
    curves = []
    count = scene.params.get("count")
    for m in scene.methods:
        for r, pair, err in _r_rows(scene, study, res, m):
            if pair is None:
                _missing(notes, scene, m, r, err)
                continue
            hsv = pair[0]["info"].get("hsv")
            if not hsv:
                _missing(notes, scene, m, r, "the reducer reports no Hankel singular values (info['hsv'])")
                continue
            hsv = np.asarray(hsv, dtype=float).ravel()[:count]
            df = {"index": np.arange(1, hsv.size + 1), "value": hsv}
            curves.append(Curve(m, study.methods[m].label, df, x="index", style="points"))
    return FigureData(scene.name, _title(scene, study, f"{model.name}: Hankel singular values"), "index $k$",
                      r"Hankel singular value $\sigma_k$", curves, xscale="linear", notes=notes)


#: the columns a table's verdict compares (smaller is better), when present
VERDICT_COLUMNS = ("max_abs_error", "max_rel_error", "h2_error", "hinf_error", "max_output_error", "l2_output_error")


def order_groups(rows) -> list:
    """The table's rows grouped by the size they are compared at: ``[(where, rows), ...]`` in
    increasing size, ``where`` reading ``"r = 4"``, or ``"8 states"`` when the rows' ROMs differ in
    states per order (first-order beside second-order: compared at equal requested first-order
    states). A row whose reduction failed (no ``r``) joins the group of its ``r_requested``, or of its
    requested states when a row of the same method gives its states per order (else it is left out).
    Used by the verdict and by the page's scoreboard, so both compare the same rows."""
    by_states = len({row["states"] // row["r"] for row in rows if row.get("r")}) > 1
    if not by_states:
        def group(row):
            return row["r_requested"]
    else:
        per = {row["method"]: row["states"] // row["r"] for row in rows if row.get("r")}

        def group(row):
            return row["r_requested"] * per[row["method"]] if row["method"] in per else None
    keys = sorted({group(row) for row in rows if group(row) is not None})
    return [(f"{k} states" if by_states else f"r = {k}", [row for row in rows if group(row) == k]) for k in keys]


def _verdict(rows, study) -> str:
    """Which method has the smallest error, per r and measure, among the table's methods.

    When the methods' ROMs differ in states per order (first-order beside second-order),
    reductions are compared at equal requested first-order states instead of equal r. Within
    a group, values are ranked by the rules of :mod:`morsuite.report.ranking`: only at equal
    states (a method that returned fewer states than asked is compared with nobody, and named
    so) and only above their floors (values at the rounding level are a tie, said as one)."""
    lines, alone = [], []
    ok = [row for row in rows if row["status"] == "ok"]
    by_states = len({row["states"] // row["r"] for row in ok if row.get("r")}) > 1
    orders = []

    def label(m):
        return study.methods[m].label

    for where, at in order_groups(ok):
        orders.append(f"{where}: " + ", ".join(f"{row['method']} r = {row['r_requested']}" for row in at))
        states = {row.get("states") for row in at}
        for row in at:
            if len(states) > 1 and sum(other.get("states") == row.get("states") for other in at) == 1:
                alone.append(f"{label(row['method'])} at {where} ({row.get('states')} states)")
        for col in VERDICT_COLUMNS:
            for g in rank(at, col):
                if g["alone"]:
                    continue
                head = f"{where}" + (f", {g['states']} states" if len(states) > 1 else "") + f", {col}: "
                if g["best"] is not None:
                    (best, who), (second, nxt) = g["ranked"][0], g["second"]
                    ratio = "tied with the next" if second == best else f"{g['ratio']:.3g}x smaller than the next"
                    flag = ""
                    if col == "hinf_error":
                        flag = _hinf_flag([row for row in at if row["method"] == who][0],
                                          [row for row in at if row["method"] == nxt][0])
                    lines.append(f"{head}{label(who)} ({best:.3g}; {ratio}){flag}")
                left = excluded_text({k: [label(m) for m in g[k]] for k in ("rounding", "untrusted", "infinite")})
                if left:
                    lines.append(head + left)
    tail = (" Not compared (no other method at their number of states): " + "; ".join(alone) + ".") if alone else ""
    if not lines:
        return (tail + _zero_note(ok, study)).strip()
    head = ("Compared at equal first-order states (a second-order ROM of order r has 2r): " + "; ".join(orders)
            + ". ") if by_states else ""
    return head + "Smallest error per measure: " + "; ".join(lines) + "." + tail + _zero_note(ok, study)


def _zero_note(rows, study) -> str:
    """The sentence naming the reductions no better than the zero model (column ``worse_than_zero``)."""
    bad = [f"{study.methods[row['method']].label} r = {row['r_requested']} ({row['worse_than_zero']})"
           for row in rows if row.get("worse_than_zero")]
    return (" Worse than the zero model T_r = 0 (error at or above the full model's norm) in the norms "
            "named: " + "; ".join(bad) + ".") if bad else ""


def _table_scene(scene, study, res):
    columns = res.summary_columns()
    rows = [res.summary_row(scene.model, m, r, scene.grid) for m in scene.methods for r in scene.rs_of(m)]
    title = _title(scene, study, f"{study.models[scene.model].name}: reductions")
    ok = [row for row in rows if row["status"] == "ok"]
    note = _verdict(rows, study) if len(scene.methods) > 1 else _zero_note(ok, study).strip()
    return TableData(scene.name, title, rows, columns=columns, note=note)


def _modes_scene(scene, study, res):
    """The modes table and the structure table of a ``modes`` scene, from what the driver computed
    (:func:`morsuite.studies.modes.compute_modes`, kept in ``res.modes_of``)."""
    from .modes import MODES_COLUMNS, STRUCTURE_COLUMNS

    data = res.modes_of.get(scene.name) or {"rows": [], "structure": [], "note": "modes not computed"}
    name = study.models[scene.model].name
    return [TableData(scene.name, _title(scene, study, f"{name}: eigenfrequencies, damping and MAC in the band"),
                      data["rows"], columns=MODES_COLUMNS, int_columns=("r", "mode"), note=data["note"]),
            TableData(f"{scene.name}_structure", _title(scene, study, f"{name}: structure of the reduced models"),
                      data["structure"], columns=STRUCTURE_COLUMNS, int_columns=("r",))]


def _time_scene(scene, study, res):
    return time_figures(scene, study, res, MAX_POINTS)


_BUILDERS = {"sigma": _freq_scene, "error": _freq_scene, "compare": _freq_scene,
             "error_vs_r": _against_r_scene, "time_vs_r": _against_r_scene, "pareto": _pareto_scene,
             "convergence": _convergence_scene, "hsv": _hsv_scene, "table": _table_scene, "time": _time_scene,
             "modes": _modes_scene, "tolerance": build_tolerance}


def build(scene, study, res) -> list:
    """The scene's outputs, FigureData or TableData, from the results ``res`` (no computing), in the
    order of :func:`output_names`."""
    out = _BUILDERS[scene.kind](scene, study, res)
    return list(out) if isinstance(out, (list, tuple)) else [out]
