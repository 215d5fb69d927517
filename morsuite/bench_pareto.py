r"""Benchmark "pareto": wall time against error for every reducer, and each run against its LU floor.

**Time against error.** For the DSMS (g = 6000), the TCOM (nc = 2000) and a
small DSMS (g = 1000, the only one where the :math:`O(n_1^3)`
``"irka-projected"`` baseline is run), every reducer reduces to
r = 2, 4, ..., 40 with *one reducer instance per (model, method)* (BT keeps
its Gramians across r). The error is
:math:`\max_\omega \sigma_{\max}(T(j\omega) - T_r(j\omega))` on 200
log-spaced :math:`\omega` of the model's band; the full response is computed
once per model and passed to :func:`morsuite.analysis.errors`.

Methods: ``irka`` (second-order ROM of order r: 2r first-order states),
``bt`` (default form, first-order square-root BT: r first-order states),
``bt-vv`` (``bt`` with ``form="vv"``, the paper's second-order velocity-velocity
BT: 2r states), ``irka-projected`` (2r states).

Time: ``time_s`` is the reducer's ``info["time_s"]`` as measured in the
sweep (a reused BT reducer pays only the truncation); ``time_standalone_s``
adds back the r-independent work paid once (``info["setup_cost"]``: BT's
LR-ADI and factor products, irka-projected's :math:`\Pi`, splitting and
projection), i.e. the cost of producing that ROM from scratch. The paper's
claim ("IRKA is more accurate and faster than BT") is checked with the
standalone times **at equal numbers of first-order states**: IRKA at r
against first-order BT at 2r, and IRKA at r against ``bt-vv`` at r.

**The floor.** At r = 20 on the DSMS (g = 6000) and the TCOM (nc = 2000) a
fresh ``irka``, ``bt`` and ``bt-vv`` run is timed, and in the same process
the floor is measured: the median time of one sparse LU (``splu`` of the
pre-assembled saddle matrix with the solver's ordering and pivot threshold)
with its right and transposed solve, at the run's own shifts (IRKA's final
shifts; the ADI shifts :math:`p` for BT, factorised at :math:`s = -p`). The
ratio is ``time_s / (lu_count x floor)``. A profiled repeat splits the run into
categories (:func:`profile_categories`, :class:`StackProfiler`: a deterministic
profiler like cProfile, but charging each interval to the first category with a
function on the call stack, so that e.g. a QR inside ``orth`` counts as
orthogonalisation): sparse LU and solves (the floor), saddle assembly, solve
accuracy checks and solver bookkeeping, orthogonalisation, dense work on
n1 x k blocks and r x r matrices, sparse products, other NumPy functions, and
the rest, Python overhead (interpreter time and inline NumPy operators in
uncategorised Python code). A cProfile repeat lists the functions with the most
own time. Profiling slows Python-heavy parts more than SuperLU, so the shares
are of the profiled run (``profile_overhead`` = profiled / plain wall time).
"""

from __future__ import annotations

import cProfile
import pstats
import time
import warnings
from pathlib import Path

import numpy as np

from .bench import benchmark
from .bench_scaling import code_state, new_figure, resolve_out_dir, save_png, write_table

__all__ = ["bench_pareto", "profile_categories", "lu_floor", "METHODS"]

#: method label -> (registry name, options, what r means)
METHODS = {
    "irka": ("irka", {}, "second-order, r x r (2r states)"),
    "bt": ("bt", {"gramian_cache": "reducer"}, "first-order square-root BT (r states)"),
    "bt-vv": ("bt", {"form": "vv", "gramian_cache": "reducer"}, "second-order velocity-velocity BT (2r states)"),
    "irka-projected": ("irka-projected", {}, "second-order, dense Pi-projected (2r states)"),
}


def _plan(quick: bool) -> dict:
    if quick:
        return {"models": [("dsms:g=200", ("irka", "bt", "bt-vv", "irka-projected")),
                           ("tcom:nc=20", ("irka", "bt"))],
                "r": (2, 4), "nfreq": 50, "floor_models": ("dsms:g=200",),
                "floor_methods": ("irka", "bt"), "floor_r": 4, "floor_samples": 2, "floor_repeat": 1}
    return {"models": [("dsms:g=6000", ("irka", "bt", "bt-vv")),
                       ("tcom:nc=2000", ("irka", "bt", "bt-vv")),
                       ("dsms:g=1000", ("irka", "bt", "bt-vv", "irka-projected"))],
            "r": tuple(range(2, 41, 2)), "nfreq": 200, "floor_models": ("dsms:g=6000", "tcom:nc=2000"),
            "floor_methods": ("irka", "bt", "bt-vv"), "floor_r": 20, "floor_samples": 8, "floor_repeat": 3}


# ---------------------------------------------------------------------------
# sweep
# ---------------------------------------------------------------------------

def standalone_time(info: dict) -> float:
    """``time_s`` plus the once-per-reducer work a reused reducer did not pay in this call."""
    t = float(info["time_s"])
    if not info.get("setup_reused"):
        return t
    tb = info.get("time_breakdown") or {}
    for key, cost in (info.get("setup_cost") or {}).items():
        t += max(0.0, float(cost) - float(tb.get(key, 0.0) or 0.0))
    return t


def _sweep(spec, fom, methods, rs, omega, H, echo):
    from . import reducers
    from .analysis import errors

    rows = []
    for label in methods:
        name, opts, meaning = METHODS[label]
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
            nominal = int(r) if (label == "bt") else 2 * int(r)
            row.update({
                "status": "ok", "r": info["r"], "states": info["states"], "states_nominal": nominal,
                "kind": info["kind"], "converged": bool(info.get("converged", True)),
                "stable": bool(info.get("stable", True)), "iterations": info.get("iterations"),
                "lu_count": info.get("lu_count"),
                "lu_count_standalone": info.get("lu_count_gramians", info.get("lu_count")),
                "time_s": info["time_s"], "time_standalone_s": standalone_time(info),
                "max_abs_error": float(err["abs_error"].max()),
                "max_rel_error": float(err["rel_error"].max()),
                "error_bound": info.get("error_bound"),
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
    from .analysis import sigma_max

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
                      "irka_converged": a["converged"], "irka_stable": a["stable"], "other_stable": b["stable"]})
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
    return pairs, summ


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
    import json

    from . import models
    from .analysis import freq_grid
    from .bench import _write_json

    out = Path(out_dir)
    res = json.loads((out / "pareto.json").read_text())
    noise = {}
    for spec, info in res["full_response"].items():
        if "noise_floor" not in info:  # older files: recompute from the full response
            fom = models.parse(spec)
            info["noise_floor"] = _noise_floor(fom.freqresp(freq_grid(fom.band, info["nfreq"])))
        noise[spec] = info["noise_floor"]
    res["pairs"], res["verdicts"] = derive_verdicts(res["rows"], noise)
    res["ratios"] = {k: v for k, v in res["ratios"].items() if k.startswith("floor ")}
    res["ratios"] = {**_verdict_ratios(res["verdicts"]), **res["ratios"]}
    files = write_outputs(res, out)
    res["files"] = [str(p) for p in files]
    _write_json(out / "pareto.json", res)
    return files


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

def lu_floor(fom, shifts, widths=(1, 1), samples: int = 8, repeat: int = 3) -> dict:
    """Median seconds of one sparse LU of the saddle matrix plus a right and a transposed solve.

    ``splu`` of the pre-assembled matrix with the options of
    ``fom.new_solver()`` (ordering, pivot threshold), at up to ``samples``
    of ``shifts`` (evenly chosen) ``repeat`` times each, alternating. Also
    the same through :meth:`SaddlePointSolver.factor` (assembly and solve
    checks included): ``solver_median_s``.
    """
    import scipy.sparse.linalg as spla
    from threadpoolctl import threadpool_limits

    shifts = np.asarray(shifts, dtype=complex).ravel()
    if shifts.size == 0:
        raise ValueError("lu_floor needs at least one shift")
    idx = np.unique(np.linspace(0, shifts.size - 1, min(samples, shifts.size)).round().astype(int))
    sample = [complex(s) for s in shifts[idx]]
    solver = fom.new_solver(cache_size=0)
    n = fom.n1 + fom.n2
    raw, via = [], []
    with threadpool_limits(limits=1, user_api="blas"):
        for k in range(repeat):
            for s in (sample if k % 2 == 0 else sample[::-1]):
                s_ = s if s.imag != 0 else s.real
                A = solver.matrix(s_)
                dt = np.complex128 if np.iscomplexobj(A.data) else np.float64
                br = np.zeros((n, widths[0]), dtype=dt)
                br[: fom.n1] = (fom.F @ np.ones((fom.m, widths[0]))) if widths[0] <= fom.m else 1.0
                bl = np.zeros((n, widths[1]), dtype=dt)
                bl[: fom.n1] = (fom.L.T @ np.ones((fom.p, widths[1]))) if widths[1] <= fom.p else 1.0
                t0 = time.perf_counter()
                lu = spla.splu(A, permc_spec=solver.permc_spec, diag_pivot_thresh=solver.diag_pivot_thresh)
                lu.solve(br)
                lu.solve(bl, trans="T")
                raw.append(time.perf_counter() - t0)
                del lu
                t0 = time.perf_counter()
                f = solver.factor(s_)
                f.solve(br[: fom.n1])
                f.solve(bl[: fom.n1], trans=True)
                via.append(time.perf_counter() - t0)
    return {"median_s": float(np.median(raw)), "solver_median_s": float(np.median(via)),
            "samples": len(raw), "shifts_sampled": [[s.real, s.imag] for s in sample],
            "definition": f"splu(S(s), permc_spec={solver.permc_spec}, diag_pivot_thresh="
                          f"{solver.diag_pivot_thresh}) + solve with {widths[0]} and transposed solve with "
                          f"{widths[1]} columns, S pre-assembled; median over {len(raw)}"}


#: profile categories in priority order: an instant of the run counts for the first category
#: that has a function on the call stack (so the SuperLU factorization inside a saddle
#: solver call counts as "sparse LU", a QR inside ``orth`` as orthogonalisation).
#: (group, category, matchers); a matcher is ("builtin", substring of "module.name" of a
#: C function, or "Type.name" for a method) or (path substring, function name or "*").
CATEGORIES = [
    ("floor", "sparse LU (SuperLU gstrf)", [("builtin", "_superlu.gstrf")]),
    ("floor", "sparse triangular solves (SuperLU)", [("builtin", "SuperLU.solve")]),
    ("sparse overhead", "saddle matrix assembly and equilibration (one pass)",
     [("linalg/saddle.py", "matrix"), ("linalg/saddle.py", "_coeffs"), ("linalg/saddle.py", "_build_pattern"),
      ("linalg/saddle.py", "_assemble_scaled"), ("linalg/saddle.py", "_diagonal_scaling"),
      ("linalg/saddle.py", "_csc")]),
    ("sparse overhead", "solve accuracy checks (backward error, refinement, condition estimate)",
     [("linalg/saddle.py", "_checked"), ("linalg/saddle.py", "_backward_error"), ("linalg/saddle.py", "_apply"),
      ("linalg/saddle.py", "_rcond_estimate")]),
    ("sparse overhead", "Ruiz equilibration",
     [("linalg/saddle.py", "_ruiz")]),
    ("sparse overhead", "SuperLU wrappers and saddle solver bookkeeping (norms, conversions)",
     [("linalg/saddle.py", "*"), ("sparse/linalg/_dsolve/", "*")]),
    ("orthogonalisation", "orthogonalisation (QR/SVD of n1 x k bases)",
     [("linalg/dense.py", "orth"), ("reducers/bt.py", "_orthonormal"), ("linalg/lradi.py", "_orthonormal_map"),
      ("linalg/lradi.py", "_gram_basis")]),
    ("dense work", "projection onto the bases (n1 x k products)",
     [("reducers/irka.py", "_project"), ("reducers/irka_projected.py", "_project"),
      ("reducers/bt.py", "_first_order"), ("reducers/bt.py", "_second_order")]),
    ("dense work", "ADI shift computation (Ritz values)",
     [("linalg/lradi.py", "projection_shifts"), ("linalg/lradi.py", "penzl_shifts"),
      ("linalg/lradi.py", "select_shifts")]),
    ("dense work", "ADI vector updates, residual and factor (n1 x k)",
     [("linalg/lradi.py", "step"), ("linalg/lradi.py", "take_block"), ("linalg/lradi.py", "factor"),
      ("linalg/lradi.py", "_append"), ("linalg/lradi.py", "_update"), ("linalg/lradi.py", "_norm2"),
      ("linalg/lradi.py", "__call__")]),
    ("dense work", "dense r-sized work (shift update, poles, reduced responses, small SVDs)",
     [("reducers/irka.py", "_update"), ("morsuite/rom.py", "*"), ("linalg/dense.py", "*"),
      ("reducers/bt.py", "_svd"), ("reducers/bt.py", "_cap"), ("analysis/response.py", "*"),
      ("numpy/linalg/", "*"), ("scipy/linalg/", "*"), ("builtin", "numpy.linalg"), ("builtin", "scipy.linalg")]),
    ("sparse overhead", "sparse-matrix products and conversions (scipy.sparse)",
     [("scipy/sparse/", "*"), ("builtin", "scipy.sparse")]),
    ("dense work", "other NumPy array functions (copies, stacking, reductions)",
     [("numpy/", "*"), ("builtin", "numpy."), ("builtin", "ndarray."), ("builtin", "ufunc.")]),
]
REST = ("Python overhead (interpreter; inline NumPy operators such as @ and + in Python code "
        "outside the categories above)")


class StackProfiler:
    """A deterministic profiler (``sys.setprofile``) that charges time to categories by call stack.

    cProfile charges each function's own time but cannot say under which caller it ran;
    here every interval between two profile events goes to the highest-priority category
    with a function on the stack (``CATEGORIES``), or to ``REST``. The time spent in the
    profile callback itself is excluded from every category.
    """

    def __init__(self, categories=None):
        self.categories = list(categories or CATEGORIES)
        self.n = len(self.categories)
        self.times = [0.0] * (self.n + 1)
        self._code = {}
        self._c = {}
        self.stack = [self.n]
        self.last = 0.0
        self.events = 0

    def _match(self, kind, text, name):
        for i, (_, _, matchers) in enumerate(self.categories):
            for path, func in matchers:
                if kind == "c" and path == "builtin" and func in text:
                    return i
                if kind == "py" and path != "builtin" and path in text and (func == "*" or func == name):
                    return i
        return self.n

    def _code_cat(self, code):
        c = self._code.get(code)
        if c is None:
            c = self._code[code] = self._match("py", code.co_filename.replace("\\", "/"), code.co_name)
        return c

    def _c_cat(self, func):
        mod = getattr(func, "__module__", None)
        owner = mod or type(getattr(func, "__self__", None)).__name__
        desc = f"{owner}.{getattr(func, '__name__', '?')}"
        c = self._c.get(desc)
        if c is None:
            c = self._c[desc] = self._match("c", desc, None)
        return c

    def __call__(self, frame, event, arg):
        now = time.perf_counter()
        st = self.stack
        self.times[st[-1]] += now - self.last
        self.events += 1
        if event == "call":
            st.append(min(st[-1], self._code_cat(frame.f_code)))
        elif event == "c_call":
            st.append(min(st[-1], self._c_cat(arg)))
        elif len(st) > 1:  # return, c_return, c_exception
            st.pop()
        self.last = time.perf_counter()

    def run(self, fn, *args, **kwargs):
        import sys

        self.last = time.perf_counter()
        sys.setprofile(self)
        try:
            return fn(*args, **kwargs)
        finally:
            sys.setprofile(None)

    def summary(self) -> dict:
        """Seconds per category and per group (plain data)."""
        cats, groups = {}, {}
        for (group, name, _), t in zip(self.categories, self.times):
            cats[name] = t
            groups[group] = groups.get(group, 0.0) + t
        cats[REST] = self.times[self.n]
        groups["Python overhead"] = self.times[self.n]
        return {"total_s": float(sum(self.times)), "categories_s": cats, "groups_s": groups,
                "events": self.events}


def profile_categories(fn, *args, top: int = 10, **kwargs) -> tuple:
    """Run ``fn`` twice: under :class:`StackProfiler` (time per category) and under cProfile
    (the ``top`` functions by own time). Returns (fn's result of the first run, summary)."""
    prof = StackProfiler()
    t0 = time.perf_counter()
    out = prof.run(fn, *args, **kwargs)
    wall = time.perf_counter() - t0
    summ = prof.summary()
    summ["wall_s"] = wall
    cp = cProfile.Profile()
    cp.enable()
    try:
        fn(*args, **kwargs)
    finally:
        cp.disable()
    st = pstats.Stats(cp)
    rows = sorted(((v[2], v[3], v[1], k) for k, v in st.stats.items()), reverse=True)[:top]
    summ["cprofile_total_s"] = float(st.total_tt)
    summ["cprofile_top_self_time"] = [
        {"function": (k[2] if k[0] == "~" else f"{Path(k[0]).name}:{k[1]}({k[2]})"), "self_s": float(tt),
         "cumulative_s": float(ct), "calls": int(nc)} for tt, ct, nc, k in rows]
    return out, summ


def _floor_shifts(label, info):
    from .reducers.base import as_complex

    if label.startswith("irka"):  # LUs at the shifts alpha (one per conjugate pair)
        s = as_complex(info["shifts"])
        return s[s.imag >= 0]
    p = as_complex(info["adi"]["controllability"]["shifts"])  # LU of S(-p) per ADI shift p
    return -p[p.imag >= 0]


def _floor_case(spec, fom, label, r, samples, repeat):
    from . import reducers

    name, opts, _ = METHODS[label]
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
    return row


# ---------------------------------------------------------------------------
# outputs
# ---------------------------------------------------------------------------

_COLORS = {"irka": "C0", "bt": "C3", "bt-vv": "C1", "irka-projected": "C2"}
_MARKERS = {"irka": "o", "bt": "s", "bt-vv": "v", "irka-projected": "D"}


def _pareto_figure(spec, rows, summaries, path):
    fig, (ax,) = new_figure()
    for label in METHODS:
        pts = sorted(((x["time_standalone_s"], x["max_abs_error"], x["r_requested"], x["states_nominal"])
                      for x in rows if x["model"] == spec and x["method"] == label and x.get("status") == "ok"),
                     key=lambda p: p[3])
        if not pts:
            continue
        t = np.array([p[0] for p in pts])
        e = np.maximum(np.array([p[1] for p in pts]), 1e-300)
        ax.plot(t, e, "-", lw=0.7, marker=_MARKERS[label], ms=4, color=_COLORS[label],
                label=f"{label}: {METHODS[label][2]}")
        for p in pts[:: max(1, len(pts) // 5)]:
            ax.annotate(f"{p[3]}", (p[0], max(p[1], 1e-300)), fontsize=6, color=_COLORS[label],
                        xytext=(3, 2), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time of the reduction from scratch [s] (BT: Gramians included)")
    ax.set_ylabel(r"$\max_\omega \sigma_{\max}(T - T_r)$ on the frequency grid")
    summ = [s for s in summaries if s["model"] == spec]
    rs = [x["r_requested"] for x in rows if x["model"] == spec and "r_requested" in x]
    title = (f"{spec}: time against error, r = {min(rs, default=0)}..{max(rs, default=0)} "
             f"(labels: first-order states asked for)")
    ax.set_title(title, fontsize=9)
    if summ:
        txt = "\n".join(f"vs {s['against']}: IRKA more accurate {s['irka_more_accurate']}/{s['pairs']}, "
                        f"faster {s['irka_faster']}/{s['pairs']}, both {s['claim_holds']}/{s['pairs']}"
                        for s in summ)
        ax.text(0.01, 0.01, txt, transform=ax.transAxes, fontsize=6.5, va="bottom")
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=6.5, loc="upper right")
    return save_png(fig, path)


def _floor_figure(floor_rows, path):
    from matplotlib import colormaps

    fig, (ax,) = new_figure(width=10.0, height=4.6)
    labels = [f"{x['model']}\n{x['method']}" for x in floor_rows]
    names = list(floor_rows[0]["profile"]["categories_s"]) if floor_rows else []
    cmap = colormaps["tab20"]
    bottom = np.zeros(len(floor_rows))
    for j, name in enumerate(names):
        frac = np.array([x["profile"]["categories_s"][name] / max(x["profile"]["total_s"], 1e-300)
                         for x in floor_rows])
        ax.bar(range(len(floor_rows)), frac, bottom=bottom, label=name if len(name) < 70 else name[:67] + "...",
               color=cmap(j % 20), width=0.7)
        bottom += frac
    for i, x in enumerate(floor_rows):
        ax.text(i, 1.01, f"ratio {x['ratio']:.2f}", ha="center", fontsize=7)
    ax.set_xticks(range(len(floor_rows)), labels, fontsize=7)
    ax.set_ylim(0, 1.1)
    ax.set_ylabel("share of the profiled run")
    ax.set_title("where the time goes; ratio = time / (LUs x one LU with its solves)", fontsize=9)
    fig.legend(loc="outside right upper", fontsize=6.5)
    return save_png(fig, path)


def _slug(spec: str) -> str:
    return spec.replace(":", "_").replace("=", "").replace(",", "_")


def write_outputs(result: dict, out_dir) -> list[Path]:
    import pandas as pd

    out = Path(out_dir)
    files = []
    rows = pd.DataFrame(result["rows"])
    cols = ["model", "method", "r_requested", "r", "states", "states_nominal", "status", "converged", "stable",
            "iterations", "lu_count", "lu_count_standalone", "time_s", "time_standalone_s", "max_abs_error",
            "max_rel_error", "error_bound", "warnings"]
    files += write_table(rows[[c for c in cols if c in rows]], out / "pareto",
                         title="pareto: wall time against max abs error",
                         note=result["note"], md_columns=cols)
    pairs = pd.DataFrame(result["pairs"])
    if not pairs.empty:
        files += write_table(pairs, out / "pareto_pairs", title="pareto: IRKA against BT at equal state counts",
                             note="times: standalone (BT with its Gramians); error: max abs over the grid")
    summ = pd.DataFrame(result["verdicts"])
    files += write_table(summ, out / "pareto_verdict", title="pareto: the paper's claim, as measured",
                         md_columns=["model", "against", "matched_on", "pairs", "irka_more_accurate", "other_more_accurate",
                                     "accuracy_ties", "irka_faster", "other_faster", "claim_holds",
                                     "median_time_ratio", "median_error_ratio", "verdict"])
    if result["floor"]:
        flat = []
        for x in result["floor"]:
            rec = {k: v for k, v in x.items() if k not in ("time_breakdown", "floor", "profile")}
            tot = max(x["profile"]["total_s"], 1e-300)
            for g, v in x["profile"]["groups_s"].items():
                rec[f"share {g}"] = v / tot
            for c, v in x["profile"]["categories_s"].items():
                rec[f"cat {c}"] = v / tot
            flat.append(rec)
        fdf = pd.DataFrame(flat)
        md = ["model", "method", "r_used", "converged", "iterations", "lu_count", "time_s", "lu_floor_s",
              "ratio", "ratio_via_solver", "profile_overhead"] + [c for c in fdf if c.startswith("share ")]
        files += write_table(fdf, out / "pareto_floor", title="pareto: each run against its LU floor (r = 20)",
                             note="ratio = time_s / (lu_count x median(one splu + right solve + transposed solve "
                                  "at the run's shifts)); shares: fractions of the profiled repeat (StackProfiler: time "
                                  "charged to the first category with a function on the call stack)",
                             md_columns=md)
        files.append(_floor_figure(result["floor"], out / "pareto_floor.png"))
    for spec in dict.fromkeys(x["model"] for x in result["rows"]):
        files.append(_pareto_figure(spec, result["rows"], result["verdicts"], out / f"pareto_{_slug(spec)}.png"))
    return files


# ---------------------------------------------------------------------------
# the benchmark
# ---------------------------------------------------------------------------

def bench_pareto(quick: bool = False, out_dir=None, *, plan: dict | None = None, echo=print) -> dict:
    """Time against error for irka, bt, bt-vv (and irka-projected on a small DSMS); floors at r = 20."""
    from . import models
    from .analysis import freq_grid

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
    ratios = _verdict_ratios(verdicts)
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
              "methods": {k: {"reducer": v[0], "options": v[1], "order": v[2]} for k, v in METHODS.items()},
              "code_start": code_start, "code": code_state(),
              "full_response": resp, "rows": rows, "pairs": pairs, "verdicts": verdicts, "floor": floor,
              "ratios": ratios, "note": note}
    files = write_outputs(result, out)
    result["files"] = [str(p) for p in files]
    return result


@benchmark("pareto")
def _registered(quick: bool) -> dict:
    """Wall time against error for irka/bt/bt-vv (irka-projected on g=1000), r = 2..40; LU floors at r = 20."""
    return bench_pareto(quick, resolve_out_dir())
