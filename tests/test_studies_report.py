"""Report layer: figures as data -> matplotlib / pgfplots, tables -> CSV / Markdown (no solving)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from morsuite.report import Curve, FigureData, pgfplots_tex, plot, read_markdown, to_markdown, write_table
from morsuite.report.writer import csv_names, write_figure


def _fig():
    w = np.logspace(-2, 0, 20)
    return FigureData(
        name="demo", title="demo figure", xlabel=r"$\omega$ (rad/s)", ylabel=r"$\sigma_{\max}(T(j\omega))$",
        curves=[Curve("full", "full", pd.DataFrame({"omega": w, "value": 1 / (1 + w)})),
                Curve("irka", "IRKA_1 & co", pd.DataFrame({"omega": w, "value": 1 / (1 + w) + 1e-3})),
                Curve("paper_irka", "paper (IRKA)", pd.DataFrame({"omega": w, "value": 0.5 / (1 + w)}),
                      style="paper")])


def test_plot_returns_handles_with_log_axes_and_labels():
    fig, ax = plot(_fig())
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    assert [ln.get_label() for ln in ax.get_lines()] == ["full", "IRKA_1 & co", "paper (IRKA)"]
    assert ax.get_lines()[2].get_linestyle() == "--"
    assert ax.get_lines()[2].get_color() == ax.get_lines()[1].get_color()   # paper curve: colour of its own
    assert "rad/s" in ax.get_xlabel()
    assert ax.get_legend() is not None


def test_log_tick_labels_are_plain_text_at_the_default_positions():
    """The report style labels log axes 10⁻², 2×10⁻¹ in plain text (no mathtext to parse) at the ticks
    matplotlib's own formatter labels, with the same numbers."""
    from matplotlib.ticker import LogFormatterSciNotation

    from morsuite.report.figures import _plain_tick

    fig, ax = plot(_fig())
    fig.canvas.draw()
    for axis in (ax.xaxis, ax.yaxis):
        for minor, default in ((False, LogFormatterSciNotation(base=10.0)),
                               (True, LogFormatterSciNotation(base=10.0, labelOnlyBase=False))):
            locs = axis.get_ticklocs(minor=minor)
            texts = [t.get_text() for t in axis.get_ticklabels(minor=minor)]
            default.set_axis(axis)
            default.set_locs(locs)
            assert len(texts) == len(locs) > 0
            for loc, text in zip(locs, texts):
                assert "$" not in text and text == _plain_tick(default(loc))
    labels = {t.get_text() for t in ax.xaxis.get_ticklabels()}
    assert {"10\u207b\u00b2", "10\u207b\u00b9", "10\u2070"} <= labels
    assert _plain_tick("$\\mathdefault{2\\times10^{-13}}$") == "2\u00d710\u207b\u00b9\u00b3"


def test_zero_and_inf_values_are_gaps_on_log_axes():
    fd = _fig()
    fd.curves[0].data.loc[3, "value"] = 0.0
    fd.curves[0].data.loc[4, "value"] = np.inf
    _, ax = plot(fd)
    y = ax.get_lines()[0].get_ydata()
    assert np.isnan(y[3]) and np.isnan(y[4])


def test_curve_needs_its_columns():
    with pytest.raises(ValueError, match="no column 'omega'"):
        Curve("x", "x", pd.DataFrame({"r": [1], "value": [1.0]}))


def test_pgfplots_reads_the_csvs_and_escapes_labels(tmp_path):
    fd = _fig()
    names = csv_names(fd)
    assert names == {"full": "demo__full.csv", "irka": "demo__irka.csv", "paper_irka": "demo__paper_irka.csv"}
    tex = pgfplots_tex(fd, names)
    assert r"xmode=log" in tex and r"ymode=log" in tex
    assert r"table[x=omega, y=value, col sep=comma] {\morsuitedir demo__irka.csv}" in tex
    assert r"IRKA\_1 \& co" in tex and r"$\sigma_{\max}(T(j\omega))$" in tex
    files = write_figure(fd, tmp_path)
    assert {f.name for f in files} == {"demo__full.csv", "demo__irka.csv", "demo__paper_irka.csv", "demo.png",
                                       "demo.pdf", "demo.tex"}
    assert list(pd.read_csv(tmp_path / "demo__full.csv").columns) == ["omega", "value"]
    assert not list(tmp_path.glob(".*"))  # no temporary files left behind


def test_single_curve_figure_uses_the_plain_name():
    fd = _fig()
    fd.curves = fd.curves[1:]
    assert csv_names(fd) == {"irka": "demo.csv", "paper_irka": "demo__paper_irka.csv"}


def test_markdown_round_trip(tmp_path):
    df = pd.DataFrame({"model": ["a|b", "c"], "r": pd.array([2, None], dtype="Int64"),
                       "err": [1.234567891e-7, float("nan")], "ok": [True, False]})
    md = to_markdown(df)
    assert md.splitlines()[1] == "|:---|---:|---:|:---|"
    back = read_markdown(md)
    assert list(back.columns) == ["model", "r", "err", "ok"]
    assert back.iloc[0].tolist() == ["a|b", "2", "1.23457e-07", "True"]
    assert back.iloc[1].tolist() == ["c", "", "", "False"]
    csv, mdp = write_table(df, tmp_path / "t", title="T")
    assert mdp.read_text().startswith("## T")
    assert len(read_markdown(mdp)) == 2 and len(pd.read_csv(csv)) == 2


def test_drawing_is_deterministic_and_ignores_the_users_rc(tmp_path):
    import matplotlib as mpl

    fd = _fig()
    formats = ("png", "pdf", "svg")
    write_figure(fd, tmp_path / "a", formats)
    with mpl.rc_context({"lines.linewidth": 5.0, "font.size": 20}):   # a user's style must not leak in
        write_figure(fd, tmp_path / "b", formats)
    for ext in formats:
        a, b = (tmp_path / "a" / f"demo.{ext}").read_bytes(), (tmp_path / "b" / f"demo.{ext}").read_bytes()
        assert a == b, ext
    assert b"CreationDate" not in (tmp_path / "a" / "demo.pdf").read_bytes()


def test_unchanged_files_are_not_rewritten(tmp_path):
    fd = _fig()
    files = write_figure(fd, tmp_path)
    stamps = {p.name: p.stat().st_mtime_ns for p in files}
    import os
    for p in files:                                 # an old mtime: a rewrite would show
        os.utime(p, ns=(1, 1))
    write_figure(fd, tmp_path)
    assert all(p.stat().st_mtime_ns == 1 for p in files), stamps
    fd.curves[1].data.loc[0, "value"] = 2.0
    write_figure(fd, tmp_path, only=["demo__irka.csv"])
    assert {p.name for p in files if p.stat().st_mtime_ns != 1} == {"demo__irka.csv"}
