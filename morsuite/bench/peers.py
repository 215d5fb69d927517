r"""Benchmark ``peers``: morsuite against pyMOR on the same models, grid, error measure and r.

pyMOR (optional extra ``peers``) has no index-3 second-order model class, so it
gets what it can take:

- ``pymor-irka-fo``: ``IRKAReductor`` on the sparse descriptor realization
  ``fom.first_order()`` (:math:`E` singular, :math:`2n_1 + n_2` states) with 2r
  states, against our ``irka`` at r, and (a second row, the same pyMOR run) against
  our ``irka-fo`` with 2r states, fresh, its start's Gramian factors included, with
  the exact H2 errors of both (``peer_h2_error``, ``ours_h2_error``, ``h2_ratio``);
  on failure the options of :data:`IRKA_FO_ATTEMPTS` are tried in turn, every
  attempt recorded;
- ``pymor-sor-irka``: ``SORIRKAReductor`` at order r on the dense
  :math:`\Pi`-projected model (order :math:`n_1 - n_2`), against our ``irka``;
- ``pymor-sobt-v``: ``SOBTvReductor`` at order r on that model, against our
  ``bt`` with ``form="vv"`` (fresh reducer, Gramians included); the same SOR-IRKA
  run is also set against our ``so-h2`` at r (fresh: its Gramian factors, its
  start candidates and its exact evaluations included; ``ours_h2_error``).

Models: dense peers on dsms(1000) and tcom(334), the first-order peer also on
dsms(6000) and tcom(2000); r = 10, 20; error :math:`\max_\omega
\sigma_{\max}(T - T_r)` on 200 log-spaced frequencies; one BLAS thread for
everyone; each peer in a forked child with a 900 s limit. ``time_ratio`` (ours /
theirs) and ``error_ratio``: below 1 is better for us; the projection's cost is
``projection_setup_s`` (``time_ratio_with_setup`` adds it to theirs). A peer
that raises, does not converge or returns an unstable model is a result.

``quick``: dsms(60), r = 4, 50 frequencies. Without pyMOR the reason is recorded
and nothing runs. Writes ``peers.json`` (through :func:`morsuite.bench.run`),
``peers.csv/.md``, ``peers_compact.md`` and ``peers.png``.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

from . import benchmark
from ..utils import atomic_write_text
from .output import code_state, new_figure, resolve_out_dir, rewrite_derived, save_png, write_table

__all__ = ["bench_peers", "pymor_available"]

#: options tried, in order, for pyMOR's first-order IRKA on the descriptor realization
IRKA_FO_ATTEMPTS = ({}, {"projection": "biorth"}, {"force_sigma_in_rhp": True})


def pymor_available() -> tuple[bool, str]:
    """(True, version) if pyMOR imports, else (False, the reason)."""
    try:
        import pymor
    except Exception as exc:  # ImportError, or a broken install
        return False, f"{type(exc).__name__}: {exc}"
    return True, str(getattr(pymor, "__version__", "?"))


def _plan(quick: bool) -> dict:
    if quick:
        return {"dense_models": ("dsms:g=60",), "sparse_models": (), "r": (4,), "nfreq": 50, "timeout_s": 60.0}
    return {"dense_models": ("dsms:g=1000", "tcom:nc=334"), "sparse_models": ("dsms:g=6000", "tcom:nc=2000"),
            "r": (10, 20), "nfreq": 200, "timeout_s": 900.0}


def _max_error(H, Hr) -> float:
    from ..analysis import sigma_max

    return float(np.max(sigma_max(H - Hr)))


def _pymor_response(rom, omega) -> np.ndarray:
    tf = rom.transfer_function
    return np.stack([np.asarray(tf.eval_tf(1j * w)).reshape(tf.dim_output, tf.dim_input) for w in omega])


def _pymor_stable(rom):
    try:
        lam = rom.poles()
        lam = lam[np.isfinite(lam)]
        return bool(np.all(lam.real < 0))
    except Exception:
        return None


def _run_peer(fn, omega, H, timeout_s=None):
    """:func:`_peer_record` in a forked child with a time limit (in-process without one)."""
    if not timeout_s:
        return _peer_record(fn, omega, H)
    import multiprocessing as mp

    try:
        ctx = mp.get_context("fork")
    except ValueError:  # pragma: no cover - no fork (Windows): run without a limit
        return _peer_record(fn, omega, H)
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(fn, omega, H, send), daemon=True)
    t0 = time.perf_counter()
    proc.start()
    send.close()
    try:
        rec = recv.recv() if recv.poll(timeout_s) else None
    except EOFError:
        rec = {"status": f"failed: the child process died (exit code {proc.exitcode})",
               "time_s": time.perf_counter() - t0}
    if rec is None:
        rec = {"status": f"timeout: no result within {timeout_s:g} s (killed)", "time_s": None,
               "timed_out_after_s": time.perf_counter() - t0}
    proc.kill()
    proc.join()
    return rec


def _child(fn, omega, H, conn):  # pragma: no cover - runs in the forked child
    try:
        conn.send(_peer_record(fn, omega, H))
    except Exception as exc:
        conn.send({"status": f"failed: {type(exc).__name__}: {str(exc)[:200]}", "time_s": None})
    finally:
        conn.close()


def _peer_record(fn, omega, H):
    """Time ``fn() -> (rom, reductor)``; error on the grid; failures as data."""
    from threadpoolctl import threadpool_limits

    rec = {}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        try:
            with threadpool_limits(limits=1, user_api="blas"):
                rom, red = fn()
            rec["time_s"] = time.perf_counter() - t0
        except Exception as exc:
            rec.update(status=f"failed: {type(exc).__name__}: {str(exc)[:200]}", time_s=time.perf_counter() - t0)
            rec["warnings"] = sorted({f"{w.category.__name__}: {str(w.message)[:120]}" for w in caught})[:5]
            return rec
    conv = [float(c) for c in (getattr(red, "conv_crit", None) or [])]
    rec.update(iterations=len(conv) or None, last_conv_crit=conv[-1] if conv else None,
               states=int(rom.order) if not hasattr(rom, "M") else 2 * int(rom.order),
               stable=_pymor_stable(rom))
    rec["warnings"] = sorted({f"{w.category.__name__}: {str(w.message)[:120]}" for w in caught})[:5]
    try:
        Hr = _pymor_response(rom, omega)
        err = _max_error(H, Hr)
    except Exception as exc:
        rec.update(status=f"failed: response of the returned model: {type(exc).__name__}: {str(exc)[:160]}")
        return rec
    rec["error"] = err
    if hasattr(rom, "to_matrices") and not hasattr(rom, "M"):
        try:  # a first-order peer model: its matrices, for the exact H2 error in the parent
            A, B, C, D, E = rom.to_matrices()
            rec["first_order"] = [np.asarray(X.toarray() if hasattr(X, "toarray") else X, dtype=float)
                                  for X in (E if E is not None else np.eye(A.shape[0]), A, B, C)]
        except Exception:  # pragma: no cover - a peer model we cannot read: no H2 error for it
            pass
    if not np.isfinite(err):
        rec["status"] = "failed: non-finite response of the returned model"
    elif conv and not conv[-1] < 1e-4:
        rec["status"] = f"not converged ({len(conv)} iterations, criterion {conv[-1]:.2e} >= tol 1e-4)"
    elif rec["stable"] is False:
        rec["status"] = "unstable reduced model"
    else:
        rec["status"] = "ok"
    return rec


def _ours(label, fom, r, omega, H):
    from .. import reducers
    from .pareto import method_of

    name, opts, _ = method_of(label)  # the registry's method, bt with its own Gramian run
    if label in ("irka-fo", "so-h2"):
        fom.cache.clear()  # standalone: its start pays for the Gramian factors, as the peer pays for all
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = reducers.make(name, fom, **opts).reduce(r)
    info = res.info
    out = {"time_s": float(info["time_s"]), "error": _max_error(H, res.rom.freqresp(omega)),
           "converged": bool(info.get("converged", True)), "stable": bool(info.get("stable", True)),
           "states": int(info["states"]), "r": int(info["r"]), "lu_count": info.get("lu_count")}
    if label in ("irka-fo", "so-h2"):
        out["h2_error"] = _h2(fom, res.rom)
    if label == "irka-fo":
        # the start (Gramian factors, SVD) does not depend on r: a reducer reused over r pays it once
        out["time_without_start_s"] = float(info["time_s"] - info["time_breakdown"].get("start", 0.0))
    return out


def _h2(fom, rom):
    """Exact H2 error (quadrature allowed 10,000 nodes: the TCOM's resonances need them), or None."""
    from ..analysis import h2_error

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return float(h2_error(fom, rom, max_nodes=10000))
    except Exception:  # an unusable peer model is recorded without an H2 error
        return None


def _row(spec, r, peer, ours_label, peer_rec, ours, setup=None, attempts=None):
    row = {"model": spec, "r": int(r), "peer": peer, "ours": ours_label,
           "status": peer_rec.get("status"), "peer_time_s": peer_rec.get("time_s"),
           "peer_error": peer_rec.get("error"), "peer_states": peer_rec.get("states"),
           "peer_iterations": peer_rec.get("iterations"), "peer_stable": peer_rec.get("stable"),
           "ours_time_s": ours["time_s"], "ours_error": ours["error"], "ours_states": ours["states"],
           "ours_r": ours["r"], "ours_converged": ours["converged"], "ours_stable": ours["stable"],
           "projection_setup_s": setup}
    _derive(row)
    if attempts is not None:
        row["options"] = attempts[-1].get("options") if attempts else None
        row["attempts"] = "; ".join(f"{a['options'] or 'defaults'}: {a['status']}" for a in attempts)
    if peer_rec.get("warnings"):
        row["peer_warnings"] = " | ".join(peer_rec["warnings"])
    return row


def _derive(row):
    """Ratios of a row: only where the peer returned a model whose error could be evaluated (a
    failure's time-to-failure is no cost of a reduced model)."""
    for k in ("time_ratio", "time_ratio_with_setup", "error_ratio"):
        row.pop(k, None)
    err, t = row.get("peer_error"), row.get("peer_time_s")
    if err is None or not np.isfinite(err) or not t:
        return row
    row["time_ratio"] = row["ours_time_s"] / t
    if row.get("projection_setup_s") is not None:
        row["time_ratio_with_setup"] = row["ours_time_s"] / (t + row["projection_setup_s"])
    if err > 0:
        row["error_ratio"] = row["ours_error"] / err
    return row


def _ratios(rows) -> dict:
    ratios = {}
    for x in rows:
        key = f"{x['model']} r={x['r']} ours/{x['peer']}" + ("" if x["ours"] in ("irka", "bt-vv") else f" ({x['ours']})")
        if x.get("time_ratio") is not None:
            ratios[f"{key} time"] = {"value": x["time_ratio"], "target": 1.0,
                                     "what": f"{x['ours']} time / {x['peer']} time ({x['status']})"}
        if x.get("error_ratio") is not None:
            ratios[f"{key} error"] = {"value": x["error_ratio"], "target": None,
                                      "what": f"{x['ours']} max abs error / {x['peer']}'s ({x['status']})"}
    return ratios


def rewrite(out_dir="results/bench") -> list[Path]:
    """Recompute the derived columns and ratios of ``out_dir``/peers.json with this code; rewrite it
    and the CSV, Markdown and PNG (the measurements are not repeated)."""
    def derive(res):
        res["rows"] = [_derive(dict(x)) for x in res["rows"]]
        res["ratios"] = _ratios(res["rows"])

    return rewrite_derived(out_dir, "peers", derive, write_outputs)


def _first_order_peer(spec, fom, r, omega, H, ours, timeout_s=None):
    import scipy.sparse as sp
    from pymor.models.iosys import LTIModel
    from pymor.reductors.h2 import IRKAReductor

    E, A, B, C = fom.first_order()
    lti = LTIModel.from_matrices(sp.csc_matrix(A), B, C, E=sp.csc_matrix(E))
    attempts, used = [], None
    for opts in IRKA_FO_ATTEMPTS:
        rec = _run_peer(lambda: (lambda red: (red.reduce(2 * r, **opts), red))(IRKAReductor(lti)), omega, H,
                        timeout_s)
        attempts.append({"options": dict(opts), **{k: v for k, v in rec.items() if k != "warnings"}})
        if rec.get("error") is not None and np.isfinite(rec["error"]):
            used = rec
            break
    used = used or rec
    row = _row(spec, r, "pymor-irka-fo", "irka", used, ours, attempts=attempts)
    row["note"] = (f"pyMOR IRKA with {2 * r} first-order states on the {2 * fom.n1 + fom.n2}-state sparse "
                   f"descriptor realization (E singular); ours: irka at r = {r} ({2 * r} states)")
    return row, attempts, used


def _first_order_row(spec, fom, r, used, attempts, ours_fo):
    """pyMOR's first-order IRKA (the record of :func:`_first_order_peer`) against our irka-fo, both with
    2r first-order states, with the exact H2 errors of both."""
    row = _row(spec, r, "pymor-irka-fo", "irka-fo", used, ours_fo, attempts=attempts)
    row["ours_h2_error"] = ours_fo.get("h2_error")
    row["ours_time_without_start_s"] = ours_fo.get("time_without_start_s")
    if row.get("peer_time_s") and row["ours_time_without_start_s"] is not None:
        row["time_ratio_without_start"] = row["ours_time_without_start_s"] / row["peer_time_s"]
    mats = used.get("first_order")
    if mats is not None:
        from ..rom import FirstOrderROM

        try:
            row["peer_h2_error"] = _h2(fom, FirstOrderROM(*mats))
        except Exception:
            row["peer_h2_error"] = None
    if row.get("ours_h2_error") and row.get("peer_h2_error"):
        row["h2_ratio"] = row["ours_h2_error"] / row["peer_h2_error"]
    row["note"] = (f"both first-order tangential IRKA with {2 * r} states: pyMOR's on the sparse descriptor "
                   f"realization, ours (irka-fo, its BT start's Gramian factors included) projector-free")
    return row


def bench_peers(quick: bool = False, out_dir=None, *, plan: dict | None = None, echo=print) -> dict:
    """pyMOR's IRKA (first-order descriptor), SOR-IRKA and SOBTv (dense Pi-projected) against ours."""
    from .. import models
    from ..analysis import freq_grid

    plan = dict(plan or _plan(quick))
    out = resolve_out_dir(out_dir)
    ok, version = pymor_available()
    result = {"plan": {k: list(v) if isinstance(v, tuple) else v for k, v in plan.items()},
              "pymor": {"available": ok, "version" if ok else "reason": version}, "rows": [], "ratios": {},
              "code_start": code_state()}
    if not ok:
        result["note"] = (f"pyMOR is not importable ({version}); install the extra: "
                          f"pip install 'morsuite[peers]'. No peer was run.")
        if echo:
            echo(f"peers: {result['note']}", flush=True)
        result["files"] = [str(p) for p in write_outputs(result, out)]
        return result
    from pymor.core.logger import set_log_levels

    set_log_levels({"pymor": "ERROR"})
    from pymor.models.iosys import SecondOrderModel
    from pymor.reductors.sobt import SOBTvReductor
    from pymor.reductors.sor_irka import SORIRKAReductor

    from ..reducers.irka.projected import IRKAProjected

    rows, details = [], {}
    specs = list(dict.fromkeys(list(plan["dense_models"]) + list(plan["sparse_models"])))
    for spec in specs:
        fom = models.parse(spec)
        omega = freq_grid(fom.band, plan["nfreq"])
        H = fom.freqresp(omega)
        dense = spec in plan["dense_models"]
        som = setup = None
        if dense:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.perf_counter()
                pm = IRKAProjected(fom).projected_model()
                setup = time.perf_counter() - t0
            Hp = np.stack([pm.transfer(1j * w) for w in omega[:: max(1, omega.size // 10)]])
            Hf = H[:: max(1, omega.size // 10)]
            details[spec] = {"projection_setup_s": setup, "projected_order": pm.order,
                             "projected_model_rel_difference": float(np.max(np.abs(Hp - Hf)) / np.max(np.abs(Hf)))}
            som = SecondOrderModel.from_matrices(pm.M, pm.D, pm.K, pm.F, pm.L)
            del pm
        for r in plan["r"]:
            ours_irka = _ours("irka", fom, r, omega, H)
            row, attempts, used = _first_order_peer(spec, fom, r, omega, H, ours_irka, plan.get("timeout_s"))
            rows.append(row)
            rows.append(_first_order_row(spec, fom, r, used, attempts, _ours("irka-fo", fom, 2 * r, omega, H)))
            if dense:
                rec = _run_peer(lambda: (lambda red: (red.reduce(r), red))(SORIRKAReductor(som)), omega, H,
                                plan.get("timeout_s"))
                rows.append(_row(spec, r, "pymor-sor-irka", "irka", rec, ours_irka, setup))
                ours_soh2 = _ours("so-h2", fom, r, omega, H)
                row = _row(spec, r, "pymor-sor-irka", "so-h2", rec, ours_soh2, setup)
                row["ours_h2_error"] = ours_soh2.get("h2_error")
                row["note"] = ("the same SOR-IRKA run against our so-h2 (structure-preserving H2 descent, "
                               "Gramian factors and its IRKA start included)")
                rows.append(row)
                ours_bt = _ours("bt-vv", fom, r, omega, H)
                rec = _run_peer(lambda: (lambda red: (red.reduce(r), red))(SOBTvReductor(som)), omega, H,
                                plan.get("timeout_s"))
                rows.append(_row(spec, r, "pymor-sobt-v", "bt-vv", rec, ours_bt, setup))
            if echo:
                for x in rows:
                    if x["model"] == spec and x["r"] == r:
                        echo(f"peers: {spec:<13} r = {r:>2} {x['peer']:<15} vs {x['ours']:<6}: {x['status']}; "
                             f"time ours/theirs {x.get('time_ratio', float('nan')):.3g}, error ours/theirs "
                             f"{x.get('error_ratio', float('nan')):.3g} (ours {x['ours_error']:.2e}, theirs "
                             f"{x['peer_error'] if x['peer_error'] is not None else float('nan'):.2e})", flush=True)
        del fom, H, som
    ratios = _ratios(rows)
    result.update(rows=rows, ratios=ratios, models=details, code=code_state(),
                  note=f"time_ratio = our time / theirs; error_ratio = our max abs error / theirs (same "
                       f"{plan['nfreq']} log-spaced frequencies of the band, sigma_max); dense peers work on the Pi-projected model, whose setup time "
                       "is projection_setup_s (time_ratio_with_setup adds it to theirs); one BLAS thread "
                       "for everyone.")
    result["files"] = [str(p) for p in write_outputs(result, out)]
    return result


def _figure(rows, path):
    fig, (ax,) = new_figure(width=max(6.0, 0.55 * len(rows) + 2.0))
    labels = [f"{x['model']}\nr={x['r']} {x['peer'].replace('pymor-', '')}" for x in rows]
    pos = np.arange(len(rows))
    t = [x.get("time_ratio") or np.nan for x in rows]
    e = [x.get("error_ratio") or np.nan for x in rows]
    ax.bar(pos - 0.2, t, 0.4, label="time ours / theirs", color="C0")
    ax.bar(pos + 0.2, e, 0.4, label="max abs error ours / theirs", color="C1")
    for i, x in enumerate(rows):
        if x.get("status") != "ok":
            ax.annotate(str(x.get("status", "")).split(":")[0][:24], (i, 1.0), fontsize=6, rotation=90,
                        ha="center", va="bottom", color="C3")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_yscale("log")
    ax.set_xticks(pos, labels, fontsize=6)
    ax.set_ylabel("ratio (below 1: morsuite better)")
    ax.set_title("morsuite against pyMOR on the same grid and error measure (red: the peer's status)", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(True, axis="y", which="major", alpha=0.3)
    return save_png(fig, path)


def write_outputs(result: dict, out_dir) -> list[Path]:
    import pandas as pd

    out = Path(out_dir)
    df = pd.DataFrame(result["rows"])
    cols = ["model", "r", "peer", "ours", "status", "peer_time_s", "ours_time_s", "time_ratio",
            "projection_setup_s", "time_ratio_with_setup", "peer_error", "ours_error", "error_ratio",
            "peer_h2_error", "ours_h2_error", "h2_ratio", "ours_time_without_start_s", "time_ratio_without_start",
            "peer_states", "ours_states", "peer_iterations", "peer_stable", "ours_converged", "attempts"]
    note = result.get("note", "")
    if not result["pymor"]["available"]:
        df = pd.DataFrame([{"peer": "pyMOR", "status": f"not run: {result['pymor']['reason']}"}])
    files = write_table(df, out / "peers", title=f"peers: morsuite against pyMOR "
                                                 f"{result['pymor'].get('version', '(not installed)')}",
                        note=note, md_columns=cols if result["pymor"]["available"] else None)
    files.append(_figure(result["rows"], out / "peers.png"))
    if result["pymor"]["available"]:
        path = out / "peers_compact.md"
        atomic_write_text(path, compact_table(result["rows"]))
        files.append(path)
    return files


def _short_status(status) -> str:
    s = str(status or "")
    if s == "ok":
        return "ok"
    if s.startswith("not converged"):
        return "not converged"
    return s.split(":")[0] + (": " + s.split(":")[1].strip().split(" ")[0] if ":" in s else "")


def compact_table(rows) -> str:
    """Markdown: per model and r, our method and the pyMOR peer side by side, with the ratios.

    time ratio = our time / theirs, error ratio = our max abs error / theirs (below 1: we are
    faster / more accurate); H2 errors where both models are first-order IRKA. A failed peer
    keeps its row with the failure as the result.
    """
    def f(x, spec):
        return "" if x is None or (isinstance(x, float) and not np.isfinite(x)) else format(x, spec)

    lines = ["| model | r | ours | states | time [s] | max abs error | H2 error | pyMOR peer | states | time [s] | "
             "max abs error | H2 error | time ratio | error ratio | peer result |",
             "|---|---:|---|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---|"]
    for row in rows:
        d = _derive(dict(row))
        lines.append(" | ".join([
            f"| {d['model']}", str(d["r"]), str(d["ours"]), str(d.get("ours_states") or ""),
            f(d.get("ours_time_s"), ".3g"), f(d.get("ours_error"), ".2e"), f(d.get("ours_h2_error"), ".4g"),
            str(d["peer"]), str(d.get("peer_states") or ""), f(d.get("peer_time_s"), ".3g"),
            f(d.get("peer_error"), ".2e"), f(d.get("peer_h2_error"), ".4g"), f(d.get("time_ratio"), ".3f"),
            f(d.get("error_ratio"), ".3g"), _short_status(d.get("status")) + " |"]))
    return "\n".join(lines) + "\n"


@benchmark("peers")
def _registered(quick: bool) -> dict:
    """morsuite against pyMOR (IRKA on the descriptor realization, SOR-IRKA and SOBTv on the projected model)."""
    return bench_peers(quick, resolve_out_dir())
