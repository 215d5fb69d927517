"""Benchmark ``bt-fl``: frequency-limited BT against ``bt`` on a sub-band, time and band error.

On each model, a fresh ``bt-fl`` reducer (default options: adaptive Gauss-Legendre rule,
first-order square root), a fresh ``bt-fl`` with ``limited="controllability"`` (the
one-sided variant, its own LR-ADI run) and a fresh ``bt`` reducer (its LR-ADI factors on
the reducer, ``gramian_cache="reducer"``) reduce to the same orders r; for each r the band error
:math:`\\max_{\\omega} \\sigma_{\\max}(T - T_r)(j\\omega)` on 400 points of the band
(:func:`morsuite.analysis.errors`; one LU per frequency, shared by both) and the
standalone times of the first call (Gramian factors included) are recorded, in one run:

- ``bt-fl MODEL time / bt time`` (and ``bt-fl one-sided ...``): wall time of a fresh
  ``reduce`` at the first order (each pays its Gramian factors), reported (no target);
- ``bt-fl MODEL band error / bt, r=R`` (and ``one-sided``): per order (issue 34: at most 1).

Models (full): tcom(2000) on (0.3, 0.6) rad/s (a sub-band holding four of its modes) and
fem_block(1000) on (1.5, 2.5) (its band (0.01, 10) holds its lowest dozen modes; the
sub-band a few in the middle); orders r = 4, 6, 8, 10 for ``form="first-order"``.
fem_block(4000) is left out: one complex SuperLU of it takes about 30 s on this machine
(measured 2026-11-27, loaded), so a rule of a few hundred nodes is hours. ``quick``:
tcom(200) and fem_block(500). Writes ``bt_fl.json`` (through :func:`morsuite.bench.run`).
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from . import benchmark

__all__ = ["bench_bt_fl"]

CASES = {False: [("tcom:nc=2000", (0.3, 0.6)), ("fem_block:n1=1000", (1.5, 2.5))],
         True: [("tcom:nc=200", (0.3, 0.6)), ("fem_block:n1=500", (1.5, 2.5))]}
ORDERS = (4, 6, 8, 10)


def _variants(band):
    """(label, options) of the compared runs: bt, bt-fl (two-sided), bt-fl with limited='controllability'."""
    return [("bt", {"gramian_cache": "reducer"}), ("bt-fl", {"band": band, "limited": "both"}),
            ("bt-fl one-sided", {"band": band, "limited": "controllability"})]


@benchmark("bt-fl")
def bench_bt_fl(quick: bool = False) -> dict:
    """``bt-fl`` against ``bt`` at equal orders on a sub-band: time and band error (ratios printed).

    Parameters
    ----------
    quick : bool
        tcom(200) and fem_block(500) instead of tcom(2000) and fem_block(1000).

    Returns
    -------
    dict
        ``rows`` (one per model, method and order) and ``ratios`` (name -> value, target,
        pass, what), the format of :mod:`morsuite.bench`.
    """
    from .. import analysis, models, reducers

    rows, ratios = [], {}
    for spec, band in CASES[quick]:
        fom = models.parse(spec)
        omega = np.linspace(band[0], band[1], 400)
        fom.freqresp(omega)  # the full model's response once, shared by both methods' errors
        times, errs = {}, {}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # StabilityWarning of an unstable FL-BT model is recorded in info
            for method, opts in _variants(band):
                t0 = time.perf_counter()
                red = reducers.make(method.split(" ")[0], fom, **opts)
                first = red.reduce(ORDERS[0])
                times[method] = time.perf_counter() - t0
                for r in ORDERS:
                    res = first if r == ORDERS[0] else red.reduce(r)
                    err = float(analysis.errors(fom, res.rom, omega)["abs_error"].max())
                    errs[method, r] = err
                    rows.append({"model": spec, "band": list(band), "method": method, "r": r, "band_error": err,
                                 "stable": res.info["stable"], "lu_count": res.info["lu_count_shared"],
                                 "nodes": res.info.get("nodes"), "time_first_s": times[method]})
        for name in ("bt-fl", "bt-fl one-sided"):
            ratio = times[name] / times["bt"]
            ratios[f"{name} {spec} time / bt time"] = {
                "value": ratio, "target": None, "pass": None,
                "what": f"fresh reduce({ORDERS[0]}) wall time, Gramian factors included: {name} / bt"}
            for r in ORDERS:
                v = errs[name, r] / errs["bt", r]
                ratios[f"{name} {spec} band error / bt, r={r}"] = {
                    "value": v, "target": 1.0, "pass": None if quick else v <= 1.0,
                    "what": f"max over {band} of sigma_max(T - T_r): {name} / bt (first-order form, equal states)"}
            print(f"{spec} band {band}: bt {times['bt']:.2f} s, {name} {times[name]:.2f} s, ratio {ratio:.2f}")
    for name, v in ratios.items():
        target = "" if v["target"] is None else f"  (target <= {v['target']}, " + (
            "not judged)" if v["pass"] is None else "pass)" if v["pass"] else "FAIL)")
        print(f"{name:55s} {v['value']:9.3g}{target}")
    return {"rows": rows, "ratios": ratios}
