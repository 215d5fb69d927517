"""Figures as data, then drawn: :class:`FigureData` -> matplotlib (PNG, PDF) and pgfplots.

A figure is a list of :class:`Curve` (columns: an x column and ``value``, plus a
legend label and a style). Plot functions draw only what they are given and
return ``(fig, ax)`` so that tests can inspect the lines; nothing here computes a
model quantity. Matplotlib is used through :class:`matplotlib.figure.Figure` (no
pyplot state, Agg canvas) and imported only when a figure is drawn.

Drawing is deterministic: the figures are drawn in matplotlib's default style plus
:data:`STYLE_RC` (a user's matplotlibrc does not leak in), and the PDF and SVG
files carry no creation date, so the same data gives the same bytes. A change of
the look that the code does not show (a new rc setting, other margins) must bump
:data:`STYLE_VERSION`; the study runner keys each figure by :func:`style` and
re-draws it when that changes.
"""

from __future__ import annotations

import contextlib
import csv
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .files import write_bytes, write_text

__all__ = ["Curve", "FigureData", "CsvSource", "plot", "render", "save", "pgfplots_tex", "style", "style_context",
           "STYLE_VERSION", "STYLE_RC"]

STYLES = ("line", "points", "paper", "full", "flagged", "level", "chosen", "steps")

#: Bump when the look of the figures changes in a way their data and :func:`style` do not show.
STYLE_VERSION = 4  # 4 (2026-12-02): a long legend beside the axes (LEGEND_INSIDE); 3: titles wrapped (TITLE_WIDTH),
# point labels thinned (MAX_LABELS); 2: plain ticks
#: titles longer than this many characters are wrapped (a title wider than the axes was cut)
TITLE_WIDTH = 64
#: a curve's point labels (``annotate``) are drawn at most this many times, evenly spread
MAX_LABELS = 5
#: a legend of more entries than this is drawn beside the axes, the figure widened by LEGEND_WIDTH inches
#: (the axes keep their size): inside, eight entries covered the curves
LEGEND_INSIDE, LEGEND_WIDTH = 5, 3.3
#: rc settings on top of matplotlib's defaults; the SVG salt fixes the ids that would be random.
STYLE_RC = {"svg.hashsalt": "morsuite"}
FIGSIZE = (6.4, 4.2)
MARGINS = {"left": 0.15, "right": 0.97, "bottom": 0.12, "top": 0.92}
DPI = {"png": 150}
#: No creation dates: a re-drawn figure is byte-identical to the last one.
METADATA = {"pdf": {"CreationDate": None}, "svg": {"Date": None}}


def style() -> dict:
    """Everything besides the data and matplotlib's version that decides a figure's pixels."""
    return {"version": STYLE_VERSION, "rc": STYLE_RC, "figsize": FIGSIZE, "margins": MARGINS, "dpi": DPI,
            "title_width": TITLE_WIDTH, "max_labels": MAX_LABELS, "legend": [LEGEND_INSIDE, LEGEND_WIDTH],
            "metadata": {k: sorted(v) for k, v in METADATA.items()}}


@contextlib.contextmanager
def style_context():
    """matplotlib's default rc plus :data:`STYLE_RC`, restored on exit."""
    import matplotlib as mpl

    with mpl.rc_context():
        mpl.rcdefaults()  # the style-blacklisted keys (backend, ...) are kept
        mpl.rcParams.update(STYLE_RC)
        yield


def _columns(data) -> list:
    return list(data.columns) if hasattr(data, "columns") else list(data)


class CsvSource:
    """Curve data in a CSV file (columns ``X,value``), read only when needed.

    The paper's figure data are overlaid as such curves: a study knows the file's
    digest (:meth:`digest`) and columns without parsing it, and parses it (with
    pandas, once) only when the figure is drawn or its CSV written. ``x`` renames the
    first non-``value`` column.
    """

    def __init__(self, path, x: str):
        self.path, self.x = Path(path), x
        with open(self.path, newline="", encoding="utf-8-sig") as fh:
            header = next(csv.reader(fh), None) or []
        others = [c for c in header if c != "value"]
        self._xcol = others[0] if others else None
        self.columns = [x, "value"] if (self._xcol is not None and "value" in header) else header
        self._frame = None

    def digest(self) -> str:
        """SHA-256 of the file's bytes (hex): the identity of the data in cache keys, without parsing it."""
        import hashlib
        return hashlib.sha256(self.path.read_bytes()).hexdigest()

    def frame(self):
        """The curve as a DataFrame with columns ``x`` and ``value`` (parsed once, then kept)."""
        if self._frame is None:
            import pandas as pd
            df = pd.read_csv(self.path)
            self._frame = df.rename(columns={self._xcol: self.x})[[self.x, "value"]]
        return self._frame

    def __getitem__(self, col):
        return self.frame()[col]


@dataclass
class Curve:
    """One curve: ``data[x]`` against ``data['value']``.

    ``data`` is a mapping of column name -> 1-D values (what studies produce), a
    DataFrame, or a :class:`CsvSource`. ``name`` is file-safe (it becomes part of the CSV name); ``label`` is the
    legend text (mathtext allowed, it is also valid LaTeX); ``style`` is "line",
    "full" (the full-order model: a thick black line under the reduced ones),
    "points" (markers joined by a thin line, e.g. a Pareto front), "paper"
    (a dashed reference curve read from the paper's figure data), "flagged"
    (large hollow markers around points of the curve ``NAME`` for a curve named
    ``flagged_NAME``: values that are not to be read as exact), "level" (a grey dotted
    horizontal line at its first value across the axes: a tolerance), "chosen" (large stars on
    points of the curve ``NAME`` for a curve named ``chosen_NAME``: the models a search chose) or
    "steps" (a staircase through its points: a best-so-far value against cost).
    """

    name: str
    label: str
    data: object           # mapping of columns, DataFrame or CsvSource
    x: str = "omega"
    style: str = "line"
    annotate: str | None = None   # a column whose values label the points (e.g. r on a Pareto plot)

    def __post_init__(self):
        if self.style not in STYLES:
            raise ValueError(f"curve style must be one of {STYLES}; got {self.style!r}")
        cols = _columns(self.data)
        for col in (self.x, "value"):
            if col not in cols:
                raise ValueError(f"curve {self.name!r}: data has no column {col!r} ({cols})")

    def frame(self):
        """The data as a DataFrame (what its CSV file holds)."""
        if isinstance(self.data, CsvSource):
            return self.data.frame()
        import pandas as pd
        return self.data if isinstance(self.data, pd.DataFrame) else pd.DataFrame(dict(self.data))


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
    #: a log x axis of whole numbers (states): ticks labelled 2, 5, 10, 20 instead of 2×10⁰
    xplain: bool = False


def _positive(y):
    y = np.asarray(y, dtype=float)
    return np.where((y > 0) & np.isfinite(y), y, np.nan)  # log axes: zero or inf is a gap, not a crash


def plot(figdata: FigureData, *, ax=None):
    """Draw ``figdata``; return ``(fig, ax)``.

    A new figure is drawn in the report style (:func:`style_context`); into a given
    ``ax`` the curves are drawn in the caller's style.
    """
    if ax is None:
        from matplotlib.figure import Figure

        with style_context():
            # fixed margins: a layout engine would double the drawing time of these simple plots
            fig = Figure(figsize=FIGSIZE)
            fig.subplots_adjust(**MARGINS)
            fig, ax = _draw(figdata, fig, fig.subplots(), legend=False)
            _plain_log_ticks(ax)
            if figdata.xplain and figdata.xscale == "log":
                from matplotlib.ticker import FuncFormatter, LogLocator
                ax.xaxis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
                ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
                ax.xaxis.set_minor_formatter(FuncFormatter(lambda v, _: ""))
            wrapped = ax.get_title().count("\n")
            if wrapped:  # room for the title's extra lines
                fig.subplots_adjust(top=MARGINS["top"] - 0.045 * wrapped)
            if figdata.curves:
                _place_legend(fig, ax)
            return fig, ax
    return _draw(figdata, ax.figure, ax)


_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


def _plain_tick(label: str) -> str:
    r"""``$\mathdefault{2\times10^{-3}}$`` -> ``2×10⁻³`` (plain text); other labels unchanged."""
    head, tail = "$\\mathdefault{", "}$"
    if not (label.startswith(head) and label.endswith(tail)):
        return label
    body = label[len(head):-len(tail)].replace("\\times", "\u00d7")
    base, sep, exp = body.partition("^{")
    return base + (exp.rstrip("}").translate(_SUPERSCRIPT) if sep else "")


def _plain_log_ticks(ax):
    """Log axes labelled ``10⁻³``, ``2×10⁻³`` in plain text: matplotlib's default labels are mathtext,
    whose parsing was a fifth of a figure's drawing time (measured 2026-11-26: 0.55-0.61 s against
    0.38-0.40 s for a PNG and a PDF of a five-curve log-log figure)."""
    from matplotlib.ticker import LogFormatterSciNotation

    class Plain(LogFormatterSciNotation):
        def __call__(self, x, pos=None):
            return _plain_tick(super().__call__(x, pos))

    for axis, scale in ((ax.xaxis, ax.get_xscale()), (ax.yaxis, ax.get_yscale())):
        if scale == "log":
            axis.set_major_formatter(Plain(base=10.0))
            axis.set_minor_formatter(Plain(base=10.0, labelOnlyBase=False))


def _draw(figdata, fig, ax, legend=True):
    colors = {}
    for c in figdata.curves:
        x = np.asarray(c.data[c.x], dtype=float)
        y = np.asarray(c.data["value"], dtype=float)
        y = _positive(y) if figdata.yscale == "log" else np.where(np.isfinite(y), y, np.nan)
        x = _positive(x) if figdata.xscale == "log" else x
        if c.style == "paper":  # dashed, in the colour of the curve it is the paper's version of
            own = colors.get(c.name[len("paper_"):], "0.35")
            ax.plot(x, y, linestyle="--", color=own, alpha=0.8, linewidth=1.2, label=c.label)
        elif c.style == "flagged":  # rings around points of the curve they flag, in its colour
            own = colors.get(c.name[len("flagged_"):], "0.35")
            ax.plot(x, y, linestyle="none", marker="o", markersize=9, markerfacecolor="none", color=own,
                    label=c.label)
        elif c.style == "points":
            (line,) = ax.plot(x, y, marker="o", markersize=4, linewidth=0.8, label=c.label)
            colors[c.name] = line.get_color()
            if c.annotate:  # at most MAX_LABELS labels a curve, its ends among them: labels must not overlap
                pts = [(xi, yi, t) for xi, yi, t in zip(x, y, c.data[c.annotate]) if np.isfinite(xi) and np.isfinite(yi)]
                keep = sorted(set(np.linspace(0, len(pts) - 1, min(MAX_LABELS, len(pts))).round().astype(int)))
                for i in keep:
                    xi, yi, t = pts[i]
                    ax.annotate(f"{c.annotate}={t}", (xi, yi), textcoords="offset points", xytext=(3, 3),
                                fontsize=6, color=line.get_color())
        elif c.style == "level":  # a tolerance: across the axes, whatever their x range
            ax.axhline(float(y[0]), color="0.4", linestyle=":", linewidth=1.2, label=c.label)
        elif c.style == "chosen":  # stars on the points of the curve they mark, in its colour
            own = colors.get(c.name[len("chosen_"):], "0.35")
            ax.plot(x, y, linestyle="none", marker="*", markersize=12, color=own, markeredgecolor="black",
                    markeredgewidth=0.5, label=c.label)
        elif c.style == "steps":
            (line,) = ax.plot(x, y, drawstyle="steps-post", marker="o", markersize=3, linewidth=1.2, label=c.label)
            colors[c.name] = line.get_color()
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
        import textwrap
        ax.set_title("\n".join(textwrap.wrap(figdata.title, TITLE_WIDTH)), fontsize=10)
    ax.grid(True, which="major", alpha=0.3)
    if figdata.curves and legend:  # a figure of its own places its legend itself (_place_legend)
        ax.legend(fontsize=8)
    return fig, ax


def _place_legend(fig, ax):
    """The legend inside the axes (matplotlib's best place), or for more than :data:`LEGEND_INSIDE` entries
    beside them: ``fig`` widened by :data:`LEGEND_WIDTH` inches, the axes unchanged in inches."""
    if len(ax.get_legend_handles_labels()[1]) <= LEGEND_INSIDE:
        ax.legend(fontsize=8)
        return
    w, h = FIGSIZE
    wide = w + LEGEND_WIDTH
    fig.set_size_inches(wide, h)
    fig.subplots_adjust(left=MARGINS["left"] * w / wide, right=MARGINS["right"] * w / wide)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)


def render(fig, fmt: str, dpi: int | None = None) -> bytes:
    """The bytes of ``fig`` as a ``fmt`` file (report style, no creation date).

    ``dpi`` applies to the raster formats (PNG; default :data:`DPI`).
    """
    dpi = (dpi or DPI[fmt]) if fmt in DPI else None
    buf = io.BytesIO()
    with style_context():
        fig.savefig(buf, format=fmt, dpi=dpi, metadata=METADATA.get(fmt))
    return buf.getvalue()


def save(fig, path_stem, formats=("png", "pdf"), dpi: int = DPI["png"]) -> list[Path]:
    """Write ``path_stem``.png and .pdf (or ``formats``); return the paths.

    ``dpi`` applies to the raster formats (PNG). Each file is written atomically,
    and not at all when it already holds these bytes
    (:func:`~morsuite.report.files.write_bytes`).
    """
    out = []
    for ext in formats:
        path = Path(f"{path_stem}.{ext}")
        write_bytes(path, render(fig, ext, dpi))
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
                 "paper": "dashed, thick", "flagged": "only marks, mark=o, mark size=3pt",
                 "level": "black!60, densely dotted", "chosen": "only marks, mark=star, mark size=4pt",
                 "steps": "const plot, mark=*, mark size=1pt"}[c.style]
        meta = ""
        if c.annotate:
            style += (", nodes near coords, point meta=explicit symbolic, "
                      "every node near coord/.append style={font=\\tiny}")
            meta = f", meta={c.annotate}"
        marks = c.style in ("points", "flagged", "chosen", "steps")
        lines.append(rf"\addplot+[{style}{'' if marks else ', no markers'}] "
                     rf"table[x={c.x}, y=value{meta}, col sep=comma] {{\morsuitedir {csv_files[c.name]}}};")
        if not c.label.startswith("_"):  # matplotlib's rule: a label starting with "_" has no legend entry
            lines.append(rf"\addlegendentry{{{_tex_text(c.label)}}}")
        else:
            lines[-1] = lines[-1].replace(r"\addplot+[", r"\addplot+[forget plot, ", 1)
    lines += [r"\end{axis}", r"\end{tikzpicture}", ""]
    return "\n".join(lines)


def write_pgfplots(figdata: FigureData, csv_files: dict, path) -> Path:
    write_text(path, pgfplots_tex(figdata, csv_files))
    return Path(path)
