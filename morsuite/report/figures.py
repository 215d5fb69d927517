"""Figures as data, then drawn: :class:`FigureData` -> matplotlib (PNG, PDF) and pgfplots.

A figure is a list of :class:`Curve` (a DataFrame with an x column and a
``value`` column, plus a legend label and a style). Plot functions draw only
what they are given and return ``(fig, ax)`` so that tests can inspect the
lines; nothing here computes a model quantity. Matplotlib is used through
:class:`matplotlib.figure.Figure` (no pyplot state, Agg canvas).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..utils import atomic_path, atomic_write_text

__all__ = ["Curve", "FigureData", "plot", "save", "pgfplots_tex"]

STYLES = ("line", "points", "paper", "full")


@dataclass
class Curve:
    """One curve: ``data[x]`` against ``data['value']``.

    ``name`` is file-safe (it becomes part of the CSV name); ``label`` is the
    legend text (mathtext allowed, it is also valid LaTeX); ``style`` is "line",
    "full" (the full-order model: a thick black line under the reduced ones),
    "points" (markers joined by a thin line, e.g. a Pareto front) or "paper"
    (a dashed reference curve read from the paper's figure data).
    """

    name: str
    label: str
    data: pd.DataFrame
    x: str = "omega"
    style: str = "line"
    annotate: str | None = None   # a column whose values label the points (e.g. r on a Pareto plot)

    def __post_init__(self):
        if self.style not in STYLES:
            raise ValueError(f"curve style must be one of {STYLES}; got {self.style!r}")
        for col in (self.x, "value"):
            if col not in self.data.columns:
                raise ValueError(f"curve {self.name!r}: data has no column {col!r} ({list(self.data.columns)})")


@dataclass
class FigureData:
    """A figure as plain data: axes labels (with units), scales, curves, notes."""

    name: str
    title: str
    xlabel: str
    ylabel: str
    curves: list
    xscale: str = "log"
    yscale: str = "log"
    notes: list = field(default_factory=list)


def _positive(y):
    y = np.asarray(y, dtype=float)
    return np.where((y > 0) & np.isfinite(y), y, np.nan)  # log axes: zero or inf is a gap, not a crash


def plot(figdata: FigureData, *, ax=None):
    """Draw ``figdata``; return ``(fig, ax)``."""
    from matplotlib.figure import Figure

    if ax is None:
        # fixed margins: a layout engine would double the drawing time of these simple plots
        fig = Figure(figsize=(6.4, 4.2))
        fig.subplots_adjust(left=0.15, right=0.97, bottom=0.12, top=0.92)
        ax = fig.subplots()
    else:
        fig = ax.figure
    colors = {}
    for c in figdata.curves:
        x = np.asarray(c.data[c.x], dtype=float)
        y = np.asarray(c.data["value"], dtype=float)
        y = _positive(y) if figdata.yscale == "log" else np.where(np.isfinite(y), y, np.nan)
        x = _positive(x) if figdata.xscale == "log" else x
        if c.style == "paper":  # dashed, in the colour of the curve it is the paper's version of
            own = colors.get(c.name[len("paper_"):], "0.35")
            ax.plot(x, y, linestyle="--", color=own, alpha=0.8, linewidth=1.2, label=c.label)
        elif c.style == "points":
            (line,) = ax.plot(x, y, marker="o", markersize=4, linewidth=0.8, label=c.label)
            colors[c.name] = line.get_color()
            if c.annotate:
                for xi, yi, t in zip(x, y, c.data[c.annotate]):
                    if np.isfinite(xi) and np.isfinite(yi):
                        ax.annotate(f"{c.annotate}={t}", (xi, yi), textcoords="offset points", xytext=(3, 3),
                                    fontsize=6, color=line.get_color())
        elif c.style == "full":
            (line,) = ax.plot(x, y, color="black", linewidth=3.0, alpha=0.45, label=c.label)
        else:
            (line,) = ax.plot(x, y, linewidth=1.3, label=c.label)
            colors[c.name] = line.get_color()
    ax.set_xscale(figdata.xscale)
    ax.set_yscale(figdata.yscale)
    if figdata.xscale == "linear" and figdata.curves and all(
            np.all(np.mod(np.asarray(c.data[c.x], dtype=float), 1) == 0) for c in figdata.curves):
        from matplotlib.ticker import MaxNLocator
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # r, states, iterations
    ax.set_xlabel(figdata.xlabel)
    ax.set_ylabel(figdata.ylabel)
    if figdata.title:
        ax.set_title(figdata.title, fontsize=10)
    ax.grid(True, which="major", alpha=0.3)
    if figdata.curves:
        ax.legend(fontsize=8)
    return fig, ax


def save(fig, path_stem, formats=("png", "pdf"), dpi: int = 150) -> list[Path]:
    """Write ``path_stem``.png and .pdf (or ``formats``) atomically; return the paths.

    ``dpi`` applies to the raster formats (PNG).
    """
    out = []
    for ext in formats:
        path = Path(f"{path_stem}.{ext}")
        with atomic_path(path, suffix=f".{ext}") as tmp:
            fig.savefig(tmp, format=ext, dpi=dpi if ext == "png" else None)
        out.append(path)
    return out


def _tex_text(text: str) -> str:
    """Escape LaTeX specials outside $...$ (labels may contain mathtext)."""
    parts = text.split("$")
    for i in range(0, len(parts), 2):
        for a, b in (("\\", r"\textbackslash{}"), ("_", r"\_"), ("%", r"\%"), ("&", r"\&"), ("#", r"\#")):
            parts[i] = parts[i].replace(a, b)
    return "$".join(parts)


def pgfplots_tex(figdata: FigureData, csv_files: dict) -> str:
    """A pgfplots picture that reads the curves' CSV files.

    ``csv_files`` maps curve name -> file name (relative to the output folder).
    The folder is ``\\morsuitedir`` (empty by default): set it with
    ``\\newcommand{\\morsuitedir}{results/NAME/}`` before ``\\input``.
    """
    mode = {"log": "log", "linear": "normal"}
    opts = [f"xmode={mode.get(figdata.xscale, 'normal')}", f"ymode={mode.get(figdata.yscale, 'normal')}",
            f"xlabel={{{_tex_text(figdata.xlabel)}}}", f"ylabel={{{_tex_text(figdata.ylabel)}}}",
            "width=12cm", "height=7cm", "grid=major", "legend pos=outer north east",
            "legend cell align=left"]
    if figdata.title:
        opts.append(f"title={{{_tex_text(figdata.title)}}}")
    lines = [f"% {figdata.name}: generated by morsuite; needs \\usepackage{{pgfplots}}",
             "% set \\morsuitedir to the folder of the CSV files, e.g. \\newcommand{\\morsuitedir}{results/NAME/}",
             r"\providecommand{\morsuitedir}{}",
             r"\begin{tikzpicture}",
             r"\begin{axis}[" + ",\n  ".join(opts) + "]"]
    for c in figdata.curves:
        style = {"line": "thick", "full": "black!50, line width=2pt", "points": "mark=*, mark size=1.5pt",
                 "paper": "dashed, thick"}[c.style]
        meta = ""
        if c.annotate:
            style += (", nodes near coords, point meta=explicit symbolic, "
                      "every node near coord/.append style={font=\\tiny}")
            meta = f", meta={c.annotate}"
        lines.append(rf"\addplot+[{style}{', no markers' if c.style != 'points' else ''}] "
                     rf"table[x={c.x}, y=value{meta}, col sep=comma] {{\morsuitedir {csv_files[c.name]}}};")
        lines.append(rf"\addlegendentry{{{_tex_text(c.label)}}}")
    lines += [r"\end{axis}", r"\end{tikzpicture}", ""]
    return "\n".join(lines)


def write_pgfplots(figdata: FigureData, csv_files: dict, path) -> Path:
    atomic_write_text(path, pgfplots_tex(figdata, csv_files))
    return Path(path)
