r"""The two figures of a ``time`` scene, from the simulations in the results (no computing).

``NAME``: :math:`y(t)` of the full model (thick grey) and :math:`y_r(t)` of each method, for
the scene's ``channel``; each curve's CSV holds every output channel (``y1 .. yp``).
``NAME_error``: :math:`\|y(t) - y_r(t)\|_2` (Euclidean over the outputs, the norm of the
summary's ``max_output_error``) on a log axis.

Long simulations are thinned for the figures and their CSV files: each curve keeps, of
each of ``max_points / 2`` stretches of samples, the one with the smallest and the one
with the largest value (and the two ends), so peaks and envelopes survive; the errors of
the summary are computed on every sample.
"""

from __future__ import annotations

import numpy as np

from ..report.figures import Curve, FigureData
from .kinds import orders_text

__all__ = ["time_figures", "thin"]


def thin(values, max_points: int) -> np.ndarray:
    """Indices (sorted) of at most ``max_points`` samples keeping each stretch's min and max."""
    v = np.asarray(values, dtype=float)
    n = v.size
    if n <= max_points:
        return np.arange(n)
    k = max(1, max_points // 2 - 1)
    edges = np.linspace(0, n, k + 1).astype(int)
    finite = np.where(np.isfinite(v), v, np.inf)
    idx = [0, n - 1]
    for a, b in zip(edges[:-1], edges[1:]):
        if b > a:
            idx += [a + int(np.argmin(finite[a:b])), a + int(np.argmax(np.where(np.isfinite(v[a:b]), v[a:b], -np.inf)))]
    return np.unique(idx)


def _input_text(spec) -> str:
    if isinstance(spec, dict):
        rest = ", ".join(f"{k}={v}" for k, v in spec.items() if k not in ("kind", "path"))
        kind = spec.get("kind", "?")
        return f"{kind}" + (f" ({rest})" if rest else "")
    kind, _, rest = str(spec).partition(":")
    if kind == "csv":
        return "measured input (" + rest.rsplit("/", 1)[-1] + ")"
    return kind + (f" ({rest})" if rest else "")


def _curve(name, label, t, y, channel, max_points, style="line"):
    keep = thin(y[:, channel], max_points)
    cols = {"t": t[keep], "value": y[keep, channel]}
    if y.shape[1] > 1:
        cols.update({f"y{j + 1}": y[keep, j] for j in range(y.shape[1])})
    return Curve(name, label, cols, x="t", style=style)


def time_figures(scene, study, res, max_points: int) -> list:
    """``[FigureData of y and y_r, FigureData of the error]`` of the time scene ``scene``."""
    notes = []
    model = study.models[scene.model]
    at = orders_text(scene)
    ch = scene.params["channel"] - 1
    what = _input_text(scene.params["input"])
    sim = res.simulation(scene.name)
    out_curves, err_curves = [], []
    if sim is None or "error" in sim:
        notes.append(f"scene {scene.name!r}: the full model's simulation failed: "
                     f"{sim['error'] if sim else 'not computed'}; nothing to draw")
    else:
        t, y = np.asarray(sim["t"], float), np.asarray(sim["y"], float)
        out_curves.append(_curve("full", f"full ($n_1 = {model.n1}$)", t, y, ch, max_points, style="full"))
        for m in scene.methods:
            r = scene.rs_of(m)[0]
            red = res.reduction(scene.model, m, r)
            e = res.sim_error(scene.name, m, r)
            if red is None or "error" in red or e is None or "error" in e:
                why = (red or {}).get("error") or (e or {}).get("error") or "not computed"
                notes.append(f"scene {scene.name!r}: {m} at r = {r}: {why}; not shown")
                continue
            got = int(red["info"]["r"])
            label = f"{study.methods[m].label} ($r = {got}$" + (f", {r} requested)" if got != r else ")")
            if e.get("growth"):
                label += ", grows"
                notes.append(f"scene {scene.name!r}: {m} at r = {r} is unstable ({e.get('unstable_poles')} poles "
                             f"in the right half-plane, growth factor {e.get('growth_factor'):.3g} over the "
                             "horizon): its output grows; growth = True in the summary")
            y_r = np.asarray(e["y_r"], float)
            out_curves.append(_curve(m, label, t, y_r, ch, max_points))
            with np.errstate(over="ignore", invalid="ignore"):
                err = np.linalg.norm(y - y_r, axis=1)
            keep = thin(err, max_points)
            err_curves.append(Curve(m, label, {"t": t[keep], "value": err[keep]}, x="t"))
    setup = f"{what}, step {scene.params['step']:g} s, {scene.params['scheme']}"
    ylab = f"$y_{{{ch + 1}}}(t)$" if model.p > 1 else "$y(t)$"
    fig_y = FigureData(scene.name, scene.title or f"{model.name}: response to {setup}, {at}", "$t$ (s)", ylab,
                       out_curves, xscale="linear", yscale="linear", notes=notes)
    fig_e = FigureData(f"{scene.name}_error", (scene.title + ": output error") if scene.title else
                       f"{model.name}: output error, {setup}, {at}", "$t$ (s)",
                       r"$\|y(t) - y_r(t)\|_2$", err_curves, xscale="linear", yscale="log", notes=[])
    return [fig_y, fig_e]
