r"""Benchmark ``irka-fo``: the first-order tangential IRKA against its LU floor, and its H2 errors.

``reducers.make("irka-fo", fom).reduce(r)`` (default options, r first-order states) on
tcom(nc=200), tcom(nc=2000), dsms(6000) and the MIMO three-chain models
``tcom:nc=150,constraints=curvature,io=points`` and ``...io=chains`` at r = 10, 20, 40,
each run standalone: the model's cache is cleared first, so that its start pays for the
Gramian factors and the SVD of first-order BT.

- Floor (:func:`~morsuite.bench.floor.bare_lu_floor`, measured right after the run):
  ``lu_count`` (the full model's LUs, certification included; not the start's) bare LUs
  with a right and a transposed solve at the run's own shifts. ``ratio`` = time / floor;
  ``ratio_without_start`` leaves out the start (Gramian factors, SVD, the BT reduced
  model), whose LUs (``start_lu_count``) and time (``start_s``) are reported apart;
  ``surrogate_s`` is the dense surrogate phase (building it included). The same model
  reduced with ``strategy="plain"`` (``plain_*``: converged, iterations, LUs, time without
  its start, and that time over the same per-LU floor) says what the surrogate saves.
- H2 errors (:func:`morsuite.analysis.h2_error`, up to 10,000 quadrature nodes, a
  reference independent of the tracking): the returned model, first-order BT with the
  same number of states (``bt``), and the paper's IRKA at r/2 (``irka``, r states), next
  to the value irka-fo tracked itself and its interpolation certificate.

``quick``: tcom(nc=60) and dsms(200) at r = 10, once. Cost: the runs, one LU per
iteration's shift for the floor, and the H2 errors (one LU per node or pole pair).
Writes ``irka_fo.json`` (through :func:`morsuite.bench.run`).
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from . import benchmark
from .floor import irka_lu_shifts, run_against_floor

__all__ = ["bench_irka_fo", "CASES"]

#: (model, r) of the full run
CASES = [(spec, r) for spec in ("tcom:nc=200", "tcom:nc=2000", "dsms:g=6000",
                                "tcom:nc=150,constraints=curvature,io=points",
                                "tcom:nc=150,constraints=curvature,io=chains") for r in (10, 20, 40)]


def _h2(fom, rom):
    from ..analysis import h2_error

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        value, d = h2_error(fom, rom, max_nodes=10000, details=True)
    return float(value), d["method"], float(d["rel_floor"])


def _case(fom, spec, r):
    from .. import reducers

    fom.cache.clear()

    def run():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = reducers.make("irka-fo", fom).reduce(r)
        run.rom = res.rom
        return res.info["time_s"], res.info

    fr = run_against_floor(fom, run, irka_lu_shifts)
    info, t = fr.info, fr.time_s
    tb = info["time_breakdown"]
    start = float(tb.get("start", 0.0))
    sur = info.get("surrogate") or {}
    row = {"model": spec, "r_requested": r, "states": info["states"], "kind": info["kind"],
           "converged": info["converged"], "iterations": info["iterations"], "lu_count": info["lu_count"],
           "time_s": t, "floor_s": fr.floor_s, "ratio": fr.ratio,
           "ratio_without_start": (t - start) / fr.floor_s, "start_s": start,
           "start_lu_count": (info.get("start") or {}).get("lu_count"), "surrogate_s": float(tb.get("surrogate", 0.0)),
           "surrogate_states": sur.get("states"), "surrogate_iterations": sur.get("iterations"),
           "surrogate_relaxed_from": sur.get("relaxed_from"),
           "newton": [(n["converged"], n["steps"]) for n in sur.get("newton", [])],
           "chord_steps": (info.get("chord") or {}).get("steps"),
           "h2_tracked": info.get("h2_error"), "certificate": info["certificate"]["residual"]}
    # the plain strategy on the same model (Gramian factors now cached): its iteration against its own floor
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain = reducers.make("irka-fo", fom, strategy="plain").reduce(r).info
    p_start = float(plain["time_breakdown"].get("start", 0.0))
    row.update({"plain_converged": plain["converged"], "plain_iterations": plain["iterations"],
                "plain_lu_count": plain["lu_count"], "plain_time_without_start_s": plain["time_s"] - p_start,
                "plain_ratio_without_start": (plain["time_s"] - p_start)
                / (fr.floor_s / max(info["lu_count"], 1) * max(plain["lu_count"], 1)),
                "plain_h2_tracked": plain.get("h2_error")})
    t0 = time.perf_counter()
    row["h2"], row["h2_route"], row["h2_rel_floor"] = _h2(fom, run.rom)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bt = reducers.make("bt", fom).reduce(r)
        irka = reducers.make("irka", fom).reduce(max(r // 2, 1))
    row["bt_states"] = bt.info["states"]
    row["h2_bt"], row["h2_bt_route"], _ = _h2(fom, bt.rom)
    row["irka_r"], row["irka_converged"] = irka.info["r"], irka.info["converged"]
    row["h2_irka"], row["h2_irka_route"], _ = _h2(fom, irka.rom) if irka.rom.is_stable() else (np.inf, None, None)
    row["h2_ratio_to_bt"] = row["h2"] / row["h2_bt"] if row["h2_bt"] > 0 else None
    row["reference_time_s"] = time.perf_counter() - t0
    return row


@benchmark("irka-fo")
def bench_irka_fo(quick: bool) -> dict:
    """irka-fo on TCOM, DSMS and MIMO three-chain models at 10/20/40 states: time over its LU floor, H2 against BT."""
    from .. import models

    cases = [("tcom:nc=60", 10), ("dsms:g=200", 10)] if quick else CASES
    rows, ratios = [], {}
    for spec, r in cases:
        fom = models.parse(spec)
        row = _case(fom, spec, r)
        rows.append(row)
        key = f"{spec} states={row['states']}"
        ratios[f"{key} time/floor"] = {
            "value": row["ratio"], "target": 1.5,
            "what": f"irka-fo wall time / ({row['lu_count']} LUs + 2 solves each, bare) including the start "
                    f"({row['start_s']:.3g} s, {row['start_lu_count']} LUs of Gramian factors if computed)"}
        ratios[f"{key} time without start/floor"] = {
            "value": row["ratio_without_start"], "target": 1.5,
            "what": "irka-fo wall time without its BT start / its own LU floor (the surrogate's dense work counts)"}
        ratios[f"{key} H2 irka-fo/bt"] = {"value": row["h2_ratio_to_bt"], "target": 1.0,
                                          "what": "exact H2 error of irka-fo / first-order BT, same states"}
        del fom
    return {"rows": rows, "ratios": ratios,
            "note": "one run per case on a shared machine (other jobs running): ratios are measured within the "
                    "run; the floor follows its run at once"}
