"""Benchmark ``compare-lus``: the sparse LUs and the time of ``morsuite compare``, item by item (issue 33).

Runs ``morsuite compare MODEL --states 12`` (the default methods) in a temporary results
folder, in this process, and reads its manifest: the LUs (``lu_count``) and time of the
full model's band response, of the model's H2 and H-infinity norms, of each reduction and
of each reduction's H2 and H-infinity error, the total, and the values (H2 errors with
their floors, H-infinity peaks found), so that a change of the LU count can be checked
against unchanged answers. Full: ``fem_block:n1=4000`` (about 6 min with SuperLU on two
cores); quick: ``fem_block:n1=1000``. Ratio: the total LU count over the target of
issue 33 (450 at n1 = 4000), lower is better; the LU count is deterministic for a given
backend, the times are not (the machine's load is recorded). Then the band response alone on one
and on two solver threads, interleaved (:func:`band_threads`): a ratio of times, not of LUs.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

from . import benchmark

#: (model, states, LU target of the whole comparison) of the full and the quick run
FULL = ("fem_block:n1=4000", 12, 450)
QUICK = ("fem_block:n1=1000", 12, None)


def _item(a, methods) -> str:
    kind = a["kind"]
    if kind == "fom_response":
        return "band response"
    if kind == "model_norm":
        return f"model {a['norm']} norm"
    if kind == "reduction":
        return f"{methods[a['id']]} reduction"
    return f"{methods.get(a.get('reduction'), a.get('reducer'))} {a['norm']} error"


def lu_rows(manifest: dict) -> list:
    """One row per computed item of a comparison's manifest: ``item``, ``lu_count``, ``time_s``,
    ``value`` (norms), ``floor`` (H2), ``status`` (reductions)."""
    rows = []
    methods = {a["id"]: "/".join(a["method_aliases"]) for a in manifest["artifacts"] if a["kind"] == "reduction"}
    for a in manifest["artifacts"]:
        if a["kind"] not in ("fom_response", "reduction", "model_norm", "norm_error"):
            continue
        rows.append({"item": _item(a, methods), "kind": a["kind"], "lu_count": int(a.get("lu_count") or 0),
                     "time_s": a.get("time_s"), "value": a.get("value"), "floor": a.get("floor"),
                     "status": a.get("status"), "iterations": a.get("iterations")})
    return rows


def compare_lus(model: str, states: int, echo=print) -> dict:
    """Run the comparison of ``model`` at ``states`` in a temporary folder; rows, total LUs, wall time."""
    from ..studies.compare import compare

    with tempfile.TemporaryDirectory(prefix="morsuite-compare-lus-") as tmp:
        t0 = time.perf_counter()
        result, _ = compare(model, [states], out=Path(tmp), name="lus", quiet=True)
        wall = time.perf_counter() - t0
        manifest = json.loads((result.outdir / "manifest.json").read_text())
    rows = lu_rows(manifest)
    if echo is not None:
        for r in rows:
            v = "" if r["value"] is None else f" value {r['value']:.10g}"
            echo(f"  {r['item']:<32} {r['lu_count']:5d} LUs {r['time_s'] or 0:8.1f} s{v}")
    return {"model": model, "states": states, "rows": rows, "lu_total": sum(r["lu_count"] for r in rows),
            "wall_s": wall}


def band_threads(model: str, n: int = 24, reps: int = 2) -> dict:
    """The full model's band response on 1 and on 2 solver threads, interleaved, each on a fresh model
    (pattern analysed before timing): the times, the ratio of the medians (2 threads over 1) and
    whether the responses are the same bits (:func:`morsuite.analysis.band_response`)."""
    import numpy as np

    from ..analysis.response import band_response, freq_grid
    from ..models import parse

    times, same = {1: [], 2: []}, True
    for _ in range(reps):
        ref = None
        for threads in (1, 2):
            fom = parse(model)
            fom.solver.factor(1j * fom.band[0])  # the pattern's analysis, not timed
            w = freq_grid(fom.band, n)
            t0 = time.perf_counter()
            H, _ = band_response(fom, w, threads=threads)
            times[threads].append(time.perf_counter() - t0)
            same = same and (ref is None or np.array_equal(H, ref))
            ref = H if ref is None else ref
    ratio = float(np.median(times[2]) / np.median(times[1]))
    return {"model": model, "frequencies": n, "times_1": times[1], "times_2": times[2], "ratio_2_over_1": ratio,
            "same_bits": bool(same)}


@benchmark("compare-lus")
def bench_compare_lus(quick: bool) -> dict:
    """LUs and time per item of `morsuite compare fem_block:n1=4000 --states 12` (quick: n1=1000); target 450 LUs."""
    model, states, target = QUICK if quick else FULL
    res = compare_lus(model, states)
    try:
        load = list(os.getloadavg())
    except (AttributeError, OSError):
        load = None
    print(f"compare-lus: {model} --states {states}: {res['lu_total']} LUs, {res['wall_s']:.0f} s; load {load}")
    # the band response's samples on the solver threads: time, not LUs (the same bits)
    thr = band_threads(model)
    print(f"compare-lus: band response of {thr['frequencies']} frequencies on 2 threads / 1 thread: "
          f"{thr['ratio_2_over_1']:.2f} (same bits: {thr['same_bits']})")
    ratios = {}
    if target is not None:
        ratios["compare_lus"] = {"value": res["lu_total"] / target, "target": 1.0,
                                 "what": f"{res['lu_total']} LUs of the comparison over the target {target}"}
    ratios["band_threads"] = {"value": thr["ratio_2_over_1"], "target": None,
                              "what": "band response time on 2 solver threads over 1 (interleaved, fresh models)"}
    return {**res, "band_threads": thr, "load_average": load, "ratios": ratios}
