r"""Benchmark ``pareto``: wall time against error for every reducer, and each run against its LU floor.

**Time against error.** Every method reduces each model to r = 2, 4, ..., 40 with
one reducer per (model, method), so BT keeps its Gramians across r: ``irka``
(2r first-order states), ``bt`` (first-order square-root BT, r states), ``bt-vv``
(``bt`` with ``form="vv"``, 2r states), ``irka-fo`` (first-order tangential IRKA, r
states; ``h2_error_tracked`` is its own exact H2 error) and ``so-h2`` (the
structure-preserving H2 descent, 2r states) on dsms(6000) and tcom(2000), and also
``irka-projected`` (2r states, :math:`O(n_1^3)`) on dsms(1000). Error:
:math:`\max_\omega \sigma_{\max}(T(j\omega) - T_r(j\omega))` on 200 log-spaced
frequencies of the band, the full response computed once per model. Time:
``time_standalone_s``, the cost of the ROM from scratch
(:func:`~morsuite.reducers.outcome.standalone_time`; LUs:
:func:`~morsuite.reducers.outcome.standalone_lu_count`).
The paper's claim (IRKA more accurate and faster than BT) is judged pairwise at
equal numbers of first-order states, and at equal r (:data:`COMPARISONS`). ``so-h2``
is set against second-order BT (``bt-vv``) at equal r in error, time and LUs
(:func:`soh2_against_bt`; its LUs include the Gramians' ADI, the BT levels'
nothing, the paper's IRKA it starts from, and its exact evaluations).

**The floor.** At r = 20 on dsms(6000) and tcom(2000) a fresh ``irka``, ``bt``,
``bt-vv`` and ``irka-fo`` run is timed against ``lu_count`` x the median of one bare LU with its
right and transposed solve at the run's own shifts
(:func:`~morsuite.bench.floor.lu_floor`, 8 shifts x 3); target 1.5. A profiled
repeat (:func:`~morsuite.bench.profiler.profile_categories`) says where the rest
goes.

``quick``: dsms(200) and tcom(20), r = 2, 4, 50 frequencies: seconds. Writes
``pareto.json`` and the tables and figures of :mod:`~morsuite.bench.pareto_report`;
:func:`rewrite` recomputes the verdicts from a saved ``pareto.json``.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from ..utils import worse_than_zero
from ..reducers.outcome import standalone_lu_count, standalone_time
from . import benchmark
from .floor import adi_lu_shifts, lu_floor, upper_half
from .output import code_state, resolve_out_dir, rewrite_derived
from .pareto_report import write_outputs
from .profiler import profile_categories

__all__ = ["bench_pareto", "derive_verdicts", "rewrite", "soh2_against_bt", "method_of", "LABELS", "BENCH_OPTIONS"]

#: options the benchmark adds to a method's reducer: each bt reducer times its own LR-ADI run
BENCH_OPTIONS = {"bt": {"gramian_cache": "reducer"}}
#: the methods of the benchmark (names of the reducers' registry, :func:`morsuite.reducers.methods`)
LABELS = ("irka", "bt", "bt-vv", "irka-projected", "irka-fo", "so-h2")


def method_of(label: str) -> tuple:
    """``(reducer, options, what r means)`` of ``label``, a method of the reducers' registry, with the
    benchmark's options (:data:`BENCH_OPTIONS`). Cost: the registry's discovery on first use."""
    from .. import reducers

    m = reducers.method(label)
    return (m.reducer, {**m.options, **BENCH_OPTIONS.get(m.reducer, {})},
            f"{m.label} ({'r' if m.states_per_order == 1 else '2r'} states)")


def _plan(quick: bool) -> dict:
    if quick:
        return {"models": [("dsms:g=200", ("irka", "bt", "bt-vv", "irka-projected", "irka-fo", "so-h2")),
                           ("tcom:nc=20", ("irka", "bt", "irka-fo"))],
                "r": (2, 4), "nfreq": 50, "floor_models": ("dsms:g=200",),
                "floor_methods": ("irka", "bt", "irka-fo"), "floor_r": 4, "floor_samples": 2, "floor_repeat": 1}
    return {"models": [("dsms:g=6000", ("irka", "bt", "bt-vv", "irka-fo", "so-h2")),
                       ("tcom:nc=2000", ("irka", "bt", "bt-vv", "irka-fo", "so-h2")),
                       ("dsms:g=1000", ("irka", "bt", "bt-vv", "irka-projected", "irka-fo"))],
            "r": tuple(range(2, 41, 2)), "nfreq": 200, "floor_models": ("dsms:g=6000", "tcom:nc=2000"),
            "floor_methods": ("irka", "bt", "bt-vv", "irka-fo"), "floor_r": 20, "floor_samples": 8,
            "floor_repeat": 3}


# ---------------------------------------------------------------------------
# sweep
# ---------------------------------------------------------------------------

def _sweep(spec, fom, methods, rs, omega, H, echo):
    from .. import reducers
    from ..analysis import errors

    rows = []
    for label in methods:
        name, opts, meaning = method_of(label)
        try:
            red = reducers.make(name, fom, **opts)
        except Exception as exc:
            rows.append({"model": spec, "method": label, "status": f"error: {type(exc).__name__}: {exc}"[:300]})
            continue
        for r in rs:
            row = {"model": spec, "method": label, "r_requested": int(r)}
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                try:
                    res = red.reduce(int(r))
                except Exception as exc:
                    row["status"] = f"error: {type(exc).__name__}: {exc}"[:300]
                    rows.append(row)
                    continue
            info = res.info
            err = errors(fom, res.rom, omega, H_full=H)
            nominal = int(r) * reducers.method(label).states_per_order
            row.update({
                "status": "ok", "r": info["r"], "states": info["states"], "states_nominal": nominal,
                "kind": info["kind"], "converged": bool(info.get("converged", True)),
                "reducer_status": info.get("status"),
                "stable": bool(info.get("stable", True)), "iterations": info.get("iterations"),
                "lu_count": info.get("lu_count"),
                "lu_count_standalone": standalone_lu_count(info), "lu_count_shared": info.get("lu_count_shared"),
                "h2_error": info.get("h2_error"), "start": info.get("start"),
                "time_s": info["time_s"], "time_standalone_s": standalone_time(info),
                "max_abs_error": float(err["abs_error"].max()),
                "max_rel_error": float(err["rel_error"].max()),
                "worse_than_zero": ",".join(worse_than_zero(band=(float(err["abs_error"].max()),
                                                                  float(err["sigma_full"].max())))),
                "error_bound": info.get("error_bound"),
                "h2_error_tracked": info.get("h2_error"),
                "warnings": len(caught)})
            rows.append(row)
        if echo:
            ok = [x for x in rows if x["method"] == label and x.get("status") == "ok"]
            if ok:
                echo(f"pareto: {spec:<13} {label:<15} r = {rs[0]}..{rs[-1]}: time "
                     f"{min(x['time_standalone_s'] for x in ok):.3g}..{max(x['time_standalone_s'] for x in ok):.3g} s, "
                     f"error {min(x['max_abs_error'] for x in ok):.2e}..{max(x['max_abs_error'] for x in ok):.2e}",
                     flush=True)
        del red
    return rows


def _noise_floor(H) -> float:
    from ..analysis import sigma_max

    return 1e3 * np.finfo(float).eps * float(np.max(sigma_max(H)))


#: comparisons of the claim: (label, other method, matched on); "states": equal nominal numbers
#: of first-order states (the fair one), "r": equal r (IRKA then has twice the states of
#: first-order BT: the reading most favourable to IRKA)
COMPARISONS = (("bt", "bt", "states"), ("bt-vv", "bt-vv", "states"), ("bt (equal r)", "bt", "r"))


def _compare(rows, spec, other, noise, tie=1.05, match="states", label=None) -> tuple[list, dict]:
    """IRKA against ``other`` at equal nominal first-order state counts (or equal r)."""
    key = "states_nominal" if match == "states" else "r_requested"
    irka = {x[key]: x for x in rows if x["method"] == "irka" and x.get("status") == "ok"}
    oth = {x[key]: x for x in rows if x["method"] == other and x.get("status") == "ok"}
    label = label or other
    pairs = []
    for s in sorted(set(irka) & set(oth)):
        a, b = irka[s], oth[s]
        ea, eb = a["max_abs_error"], b["max_abs_error"]
        ta, tb = a["time_standalone_s"], b["time_standalone_s"]
        if max(ea, eb) <= noise:
            acc = "tie (both at roundoff)"
        elif max(ea, eb) <= tie * min(ea, eb):
            acc = "tie (within 5%)"
        else:
            acc = "irka" if ea < eb else other
        fast = "tie (within 5%)" if max(ta, tb) <= tie * min(ta, tb) else ("irka" if ta < tb else other)
        pairs.append({"model": spec, "against": label, "matched_on": match, "states": a["states_nominal"],
                      "other_states": b["states_nominal"], "irka_r": a["r_requested"],
                      "other_r": b["r_requested"], "irka_states_returned": a.get("states"),
                      "other_states_returned": b.get("states"), "irka_error": ea, "other_error": eb,
                      "error_ratio": ea / eb if eb > 0 else float("inf"),
                      "irka_time_s": ta, "other_time_s": tb, "time_ratio": ta / tb if tb > 0 else float("inf"),
                      "more_accurate": acc, "faster": fast,
                      "claim_holds": bool(acc == "irka" and fast == "irka"),
                      "irka_converged": a["converged"], "irka_stable": a["stable"], "other_stable": b["stable"],
                      "irka_worse_than_zero": a.get("worse_than_zero") or "",
                      "other_worse_than_zero": b.get("worse_than_zero") or ""})
    n = len(pairs)
    summ = {"model": spec, "against": label, "matched_on": match, "pairs": n,
            "irka_more_accurate": sum(p["more_accurate"] == "irka" for p in pairs),
            "other_more_accurate": sum(p["more_accurate"] == other for p in pairs),
            "accuracy_ties": sum(p["more_accurate"].startswith("tie") for p in pairs),
            "irka_faster": sum(p["faster"] == "irka" for p in pairs),
            "other_faster": sum(p["faster"] == other for p in pairs),
            "claim_holds": sum(p["claim_holds"] for p in pairs)}
    if n:
        summ["median_time_ratio"] = float(np.median([p["time_ratio"] for p in pairs]))
        summ["median_error_ratio"] = float(np.median([p["error_ratio"] for p in pairs]))
        verdict = ("holds" if summ["claim_holds"] == n else "refuted" if summ["claim_holds"] == 0
                   else "holds in part")
        what = "state counts" if match == "states" else "values of r (IRKA: 2r states, bt: r)"
        summ["verdict"] = (f"claim {verdict}: IRKA more accurate at {summ['irka_more_accurate']}/{n} {what} "
                           f"({other} at {summ['other_more_accurate']}, ties {summ['accuracy_ties']}), faster at "
                           f"{summ['irka_faster']}/{n} ({other} at {summ['other_faster']}); both at "
                           f"{summ['claim_holds']}/{n}; median time ratio irka/{other} "
                           f"{summ['median_time_ratio']:.3g}, median error ratio {summ['median_error_ratio']:.3g}")
    else:
        summ["verdict"] = "no comparable pairs"
    where = "states" if match == "states" else "r"
    zero = [f"{who} at {where} = {p[key if match == 'r' else 'states']}" for p in pairs
            for who, col, key in (("irka", "irka_worse_than_zero", "irka_r"),
                                  (other, "other_worse_than_zero", "other_r")) if p[col]]
    summ["worse_than_zero"] = zero
    if zero:
        summ["verdict"] += (f"; worse than the zero model in the band norm (max error >= max sigma(T)): "
                            f"{', '.join(zero)}")
    return pairs, summ


def soh2_against_bt(rows) -> list:
    """so-h2 against second-order BT (``bt-vv``) at equal r: band error, standalone time and LUs (so-h2's
    include the Gramians' ADI LUs, the BT levels and the paper's IRKA it starts from)."""
    out = []
    for spec in dict.fromkeys(x["model"] for x in rows):
        ok = [x for x in rows if x["model"] == spec and x.get("status") == "ok"]
        a = {x["r_requested"]: x for x in ok if x["method"] == "so-h2"}
        b = {x["r_requested"]: x for x in ok if x["method"] == "bt-vv"}
        for r in sorted(set(a) & set(b)):
            x, y = a[r], b[r]
            out.append({"model": spec, "r": r, "so_h2_error": x["max_abs_error"], "bt_vv_error": y["max_abs_error"],
                        "error_ratio": x["max_abs_error"] / y["max_abs_error"] if y["max_abs_error"] > 0 else np.inf,
                        "so_h2_h2_error": x.get("h2_error"), "so_h2_start": x.get("start"),
                        "so_h2_time_s": x["time_standalone_s"], "bt_vv_time_s": y["time_standalone_s"],
                        "time_ratio": x["time_standalone_s"] / max(y["time_standalone_s"], 1e-300),
                        "so_h2_lus": x["lu_count_standalone"], "bt_vv_lus": y["lu_count_standalone"],
                        "lu_ratio": x["lu_count_standalone"] / max(y["lu_count_standalone"], 1),
                        "so_h2_iterations": x.get("iterations")})
    return out


def _soh2_ratios(cmp) -> dict:
    ratios = {}
    for spec in dict.fromkeys(c["model"] for c in cmp):
        cs = [c for c in cmp if c["model"] == spec]
        for key, what in (("time_ratio", "standalone time"), ("lu_ratio", "LUs"), ("error_ratio", "max abs error")):
            ratios[f"{spec} so-h2/bt-vv {what} (median)"] = {
                "value": float(np.median([c[key] for c in cs])), "target": None,
                "what": f"median over {len(cs)} values of r of so-h2's {what} / second-order BT's (bt-vv)"}
    return ratios


def derive_verdicts(rows, noise: dict) -> tuple[list, list]:
    """All pairs and verdicts of :data:`COMPARISONS` from the sweep rows; ``noise``: model -> roundoff level."""
    pairs, verdicts = [], []
    for spec in dict.fromkeys(x["model"] for x in rows):
        mrows = [x for x in rows if x["model"] == spec]
        methods = {x["method"] for x in mrows}
        for label, other, match in COMPARISONS:
            if other in methods and "irka" in methods:
                p, s = _compare(mrows, spec, other, noise.get(spec, 0.0), match=match, label=label)
                pairs += p
                verdicts.append(s)
    return pairs, verdicts


def rewrite(out_dir="results/bench") -> list[Path]:
    """Recompute the derived tables (pairs, verdicts, their ratios) of ``out_dir``/pareto.json with
    this code, and rewrite the JSON and every output file; the measurements are not repeated."""
    from .. import models
    from ..analysis import freq_grid

    def derive(res):
        noise = {}
        for spec, info in res["full_response"].items():
            if "noise_floor" not in info:  # older files: recompute from the full response
                fom = models.parse(spec)
                info["noise_floor"] = _noise_floor(fom.freqresp(freq_grid(fom.band, info["nfreq"])))
            noise[spec] = info["noise_floor"]
        res["pairs"], res["verdicts"] = derive_verdicts(res["rows"], noise)
        floor_ratios = {k: v for k, v in res["ratios"].items() if k.startswith("floor ")}
        res["so_h2"] = soh2_against_bt(res["rows"])
        res["ratios"] = {**_verdict_ratios(res["verdicts"]), **_soh2_ratios(res["so_h2"]), **floor_ratios}

    return rewrite_derived(out_dir, "pareto", derive, write_outputs)


def _verdict_ratios(verdicts) -> dict:
    ratios = {}
    for s in verdicts:
        if s["pairs"]:
            what = "equal-state" if s.get("matched_on", "states") == "states" else "equal-r"
            ratios[f"{s['model']} irka/{s['against']} time (median)"] = {
                "value": s["median_time_ratio"], "target": 1.0,
                "what": f"median over {s['pairs']} {what} pairs of IRKA time / {s['against']} time "
                        f"(standalone); the paper claims < 1"}
            ratios[f"{s['model']} irka/{s['against']} error (median)"] = {
                "value": s["median_error_ratio"], "target": 1.0,
                "what": f"median over {s['pairs']} {what} pairs of IRKA max abs error / {s['against']}'s; "
                        f"the paper claims < 1"}
    return ratios


# ---------------------------------------------------------------------------
# floor
# ---------------------------------------------------------------------------

def _floor_shifts(label, info):
    if label.startswith("irka"):  # LUs at the final shifts alpha (one per conjugate pair)
        return upper_half(info["shifts"])
    return adi_lu_shifts(info)


def _floor_case(spec, fom, label, r, samples, repeat):
    from .. import reducers

    name, opts, _ = method_of(label)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = reducers.make(name, fom, **opts).reduce(r)
        info = res.info
        shifts = _floor_shifts(label, info)
        # IRKA solves one tangential column each way; LR-ADI solves m and p columns
        widths = (fom.m, fom.p) if label.startswith("bt") else (1, 1)
        fl = lu_floor(fom, shifts, widths=widths, samples=samples, repeat=repeat)
        res_p, cats = profile_categories(lambda: reducers.make(name, fom, **opts).reduce(r))
        t_prof = cats["wall_s"]
    lu = int(info["lu_count"])
    t = float(info["time_s"])
    floor_total = lu * fl["median_s"]
    row = {"model": spec, "method": label, "r": int(r), "r_used": info["r"], "states": info["states"],
           "converged": info.get("converged"), "iterations": info.get("iterations"), "lu_count": lu,
           "time_s": t, "lu_floor_s": fl["median_s"], "lu_floor_via_solver_s": fl["solver_median_s"],
           "floor_total_s": floor_total, "ratio": t / floor_total,
           "ratio_via_solver": t / (lu * fl["solver_median_s"]),
           "rest_s": t - floor_total, "profiled_time_s": t_prof, "profile_overhead": t_prof / t,
           "profiled_lu_count": int(res_p.info["lu_count"]),
           "time_breakdown": info.get("time_breakdown"), "floor": fl, "profile": cats}
    start = (info.get("time_breakdown") or {}).get("start")
    if start is not None:  # irka-fo: its BT start (Gramian factors, SVD) is reported apart
        row["start_s"] = float(start)
        row["ratio_without_start"] = (t - start) / floor_total
    return row


# ---------------------------------------------------------------------------
# the benchmark
# ---------------------------------------------------------------------------

def bench_pareto(quick: bool = False, out_dir=None, *, plan: dict | None = None, echo=print) -> dict:
    """Time against error for irka, bt, bt-vv, so-h2 (and irka-projected on a small DSMS); floors at r = 20."""
    from .. import models
    from ..analysis import freq_grid

    plan = dict(plan or _plan(quick))
    out = resolve_out_dir(out_dir)
    code_start = code_state()
    rows, pairs, verdicts, resp = [], [], [], {}
    for spec, methods in plan["models"]:
        fom = models.parse(spec)
        omega = freq_grid(fom.band, plan["nfreq"])
        t0 = time.perf_counter()
        H = fom.freqresp(omega)
        resp[spec] = {"time_s": time.perf_counter() - t0, "n1": fom.n1, "n2": fom.n2, "band": list(fom.band),
                      "nfreq": int(omega.size)}
        resp[spec]["noise_floor"] = _noise_floor(H)
        mrows = _sweep(spec, fom, methods, list(plan["r"]), omega, H, echo)
        rows += mrows
        mp, mv = derive_verdicts(mrows, {spec: resp[spec]["noise_floor"]})
        pairs += mp
        verdicts += mv
        for s in mv if echo else ():
            other = s["against"]
            how = "equal first-order states" if s["matched_on"] == "states" else "equal r"
            echo(f"pareto: {spec}: IRKA vs {other} at {how}: {s['verdict']}", flush=True)
            for q in (q for q in mp if q["against"] == other):
                echo(f"    irka {q['states']:>3} states, {other} {q['other_states']:>3}: error irka "
                     f"{q['irka_error']:.2e} {other} {q['other_error']:.2e} -> {q['more_accurate']}; time irka "
                     f"{q['irka_time_s']:.3g} s {other} {q['other_time_s']:.3g} s -> {q['faster']}", flush=True)
        del fom, H
    floor = []
    for spec in plan["floor_models"]:
        fom = models.parse(spec)
        for label in plan["floor_methods"]:
            row = _floor_case(spec, fom, label, plan["floor_r"], plan["floor_samples"], plan["floor_repeat"])
            floor.append(row)
            if echo:
                g = row["profile"]["groups_s"]
                tot = max(row["profile"]["total_s"], 1e-300)
                echo(f"pareto floor: {spec} {label} r = {plan['floor_r']}: {row['time_s']:.3g} s, "
                     f"{row['lu_count']} LUs x {1e3 * row['lu_floor_s']:.3g} ms -> ratio {row['ratio']:.2f}; "
                     + ", ".join(f"{k} {100 * v / tot:.0f}%" for k, v in g.items()), flush=True)
        del fom
    soh2 = soh2_against_bt(rows)
    ratios = {**_verdict_ratios(verdicts), **_soh2_ratios(soh2)}
    for x in floor:
        ratios[f"floor {x['model']} {x['method']} r={x['r']}"] = {
            "value": x["ratio"], "target": 1.5,
            "what": f"{x['method']} wall time / ({x['lu_count']} LUs x {1e3 * x['lu_floor_s']:.3g} ms one LU "
                    f"with its right and transposed solve)"}
    note = ("time_standalone_s: cost of the ROM from scratch (a reused BT reducer's Gramians and "
            "irka-projected's projection added back); states_nominal: first-order states asked for "
            "(irka, bt-vv, irka-projected: 2r; bt: r); states: what the reducer returned (it caps r where "
            f"the model does not support it). Error: max over {plan['nfreq']} log-spaced frequencies of the "
            "band of sigma_max(T - T_r).")
    result = {"plan": {k: ([list(m) if isinstance(m, tuple) else m for m in v] if isinstance(v, (list, tuple)) else v)
                       for k, v in plan.items()},
              "methods": {k: dict(zip(("reducer", "options", "order"), method_of(k))) for k in LABELS},
              "code_start": code_start, "code": code_state(),
              "full_response": resp, "rows": rows, "pairs": pairs, "verdicts": verdicts, "so_h2": soh2,
              "floor": floor,
              "ratios": ratios, "note": note}
    files = write_outputs(result, out)
    result["files"] = [str(p) for p in files]
    return result


@benchmark("pareto")
def _registered(quick: bool) -> dict:
    """Wall time against error for irka/bt/bt-vv/irka-fo/so-h2 (irka-projected on g=1000), r = 2..40; LU floors at r = 20."""
    return bench_pareto(quick, resolve_out_dir())
