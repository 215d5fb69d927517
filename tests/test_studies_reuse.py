"""Re-runs redo nothing: figures and tables are artifacts keyed by their content.

An unchanged study re-run draws nothing and touches no file; a change of one
scene re-draws that scene only; a deleted file is made again; ``rerender`` draws
everything and the bytes come out the same. Subprocesses check what a cached run
imports and that ``python -m morsuite`` is the command line.

Small model: dsms(g = 200), r = 4, 40 frequencies.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from morsuite.report import writer
from morsuite.studies import run

REPO = Path(__file__).resolve().parents[1]

SPEC = """
name = "reuse"
title = "reuse study"

[models]
dsms = "dsms:g=200"

[grids]
g = { band = [1e-2, 1.0], n = 40 }

[methods.irka]
label = "IRKA"
options = { tol = 1e-6 }

[[scenes]]
name = "sig"
kind = "sigma"
model = "dsms"
grid = "g"
r = 4
paper_csv = { full = "paper_full.csv" }

[[scenes]]
name = "err"
kind = "error"
model = "dsms"
grid = "g"
r = 4

[[scenes]]
name = "conv"
kind = "convergence"
model = "dsms"
r = 4

[[scenes]]
name = "tab"
kind = "table"
model = "dsms"
grid = "g"
r = 4
"""

FIGURES = ("sig", "err", "conv")


def _snapshot(outdir: Path) -> dict:
    """name -> (bytes, mtime_ns) of every output file (the manifest aside: it records each run)."""
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(outdir.iterdir())
            if p.is_file() and p.name != "manifest.json"}


def _outputs(manifest) -> dict:
    return {a["id"]: a for a in manifest["artifacts"] if a["kind"] in ("figure", "table")}


@pytest.fixture(scope="module")
def settled(tmp_path_factory):
    """A results folder after two runs: the first computes, the second marks the rows cached."""
    tmp = tmp_path_factory.mktemp("settled")
    (tmp / "paper_full.csv").write_text("omega,value\n0.01,1.0\n0.1,0.5\n1.0,0.25\n")
    spec = tmp / "reuse.toml"
    spec.write_text(SPEC)
    run(spec, out=tmp / "results", quiet=True)
    run(spec, out=tmp / "results", quiet=True)
    return tmp


@pytest.fixture
def study(settled, tmp_path):
    """A private copy of the settled folder (mtimes kept) and its spec."""
    shutil.copytree(settled, tmp_path / "s", copy_function=shutil.copy2)
    return tmp_path / "s" / "reuse.toml", tmp_path / "s" / "results"


@pytest.fixture
def draws(monkeypatch):
    """Names of the figures drawn (matplotlib called) during the test."""
    drawn = []
    real = writer.plot

    def counting(figdata, **kw):
        drawn.append(figdata.name)
        return real(figdata, **kw)
    monkeypatch.setattr(writer, "plot", counting)
    return drawn


def test_unchanged_rerun_draws_nothing_and_touches_nothing(study, draws):
    spec, results = study
    before = _snapshot(results / "reuse")
    res = run(spec, out=results, quiet=True)
    assert draws == []
    assert _snapshot(results / "reuse") == before          # same bytes, same mtimes
    outs = _outputs(res.manifest)
    assert set(outs) == {"figure/sig", "figure/err", "figure/conv", "table/tab", "table/summary"}
    assert all(o["reused"] and not o["rendered"] and not o["changed"] for o in outs.values())
    assert set(res.manifest["reused"]) == {a["id"] for a in res.manifest["artifacts"]}
    assert res.manifest["computed"] == []
    assert len(res.summary) == 1 and bool(res.summary.cached.iloc[0])   # the DataFrame is still there


def test_manifest_records_each_output_with_key_files_and_inputs(study):
    spec, results = study
    m = json.loads((results / "reuse" / "manifest.json").read_text())
    outs = _outputs(m)
    ids = {a["id"] for a in m["artifacts"]}
    for o in outs.values():
        assert len(o["key"]) == 64 and o["inputs"] and set(o["inputs"]) <= ids
        for name, sha in o["files"].items():
            import hashlib
            assert hashlib.sha256((results / "reuse" / name).read_bytes()).hexdigest() == sha
    assert set(outs["figure/sig"]["files"]) == {"sig__full.csv", "sig__irka.csv", "sig__paper_full.csv",
                                                "sig.png", "sig.pdf", "sig.tex"}
    assert set(outs["table/summary"]["files"]) == {"summary.csv", "summary.md"}
    assert outs["figure/sig"]["formats"] == ["png", "pdf"]
    # every file of the run belongs to one output (or is the manifest)
    owned = {n for o in outs.values() for n in o["files"]}
    page = next(a for a in m["artifacts"] if a["kind"] == "page")
    assert set(page["files"]) == {"index.html"} and len(page["key"]) == 64
    assert owned | {"manifest.json", "index.html"} == set(m["files"]) | {"manifest.json"}


def test_changed_title_redraws_that_figure_only(study, draws):
    spec, results = study
    spec.write_text(SPEC.replace('name = "err"\n', 'name = "err"\ntitle = "another title"\n'))
    before = _snapshot(results / "reuse")
    res = run(spec, out=results, quiet=True)
    assert draws == ["err"]
    outs = _outputs(res.manifest)
    assert [i for i, o in outs.items() if not o["reused"]] == ["figure/err"]
    # the curve did not change: its CSV is left as it was; the image and the .tex are new
    assert sorted(outs["figure/err"]["changed"]) == ["err.pdf", "err.png", "err.tex"]
    after = _snapshot(results / "reuse")
    # the study's page shows the figure's title: it changes with it
    assert {n for n in after if after[n] != before[n]} == {"err.pdf", "err.png", "err.tex", "index.html"}


def test_changed_r_redraws_that_scene_and_the_summary(study, draws):
    spec, results = study
    spec.write_text(SPEC.replace('name = "conv"\nkind = "convergence"\nmodel = "dsms"\nr = 4',
                                 'name = "conv"\nkind = "convergence"\nmodel = "dsms"\nr = [4, 5]'))
    res = run(spec, out=results, quiet=True)
    assert draws == ["conv"]
    outs = _outputs(res.manifest)
    assert sorted(i for i, o in outs.items() if not o["reused"]) == ["figure/conv", "table/summary"]
    assert len(res.summary) == 2                                   # the new reduction r = 5


def test_deleted_or_edited_file_is_made_again(study, draws):
    spec, results = study
    out = results / "reuse"
    before = _snapshot(out)
    (out / "err.png").unlink()
    (out / "conv.csv").write_text("edited by hand\n")
    res = run(spec, out=results, quiet=True)
    assert draws == ["err"]                                        # conv's CSV needs no drawing
    outs = _outputs(res.manifest)
    assert outs["figure/err"]["rendered"] == ["err.png"] and outs["figure/conv"]["rendered"] == ["conv.csv"]
    assert sorted(i for i, o in outs.items() if not o["reused"]) == ["figure/conv", "figure/err"]
    after = _snapshot(out)
    assert after["err.png"][0] == before["err.png"][0] and after["conv.csv"][0] == before["conv.csv"][0]
    assert {n for n in after if after[n] != before[n]} == {"err.png", "conv.csv"}   # the rest untouched


def test_rerender_draws_everything_and_the_bytes_are_the_same(study, draws):
    spec, results = study
    before = _snapshot(results / "reuse")
    res = run(spec, out=results, quiet=True, rerender=True)
    assert sorted(draws) == sorted(FIGURES)
    assert res.manifest["rerender"] is True
    assert not any(o["reused"] for o in _outputs(res.manifest).values())
    assert _snapshot(results / "reuse") == before     # deterministic drawing: nothing had to be replaced


def test_figures_drawn_on_two_processes_are_the_serial_ones(study):
    """render_jobs = 2 (forked drawing processes, as `morsuite run` asks when nothing timed runs):
    the same files, bytes and output records as the serial drawing."""
    spec, results = study
    before = _snapshot(results / "reuse")
    serial = _outputs(run(spec, out=results, quiet=True, rerender=True).manifest)
    forked = _outputs(run(spec, out=results, quiet=True, rerender=True, render_jobs=2).manifest)
    assert _snapshot(results / "reuse") == before
    assert list(forked) == list(serial)
    for oid, rec in serial.items():
        assert {k: v for k, v in forked[oid].items() if k != "time_s"} == {k: v for k, v in rec.items() if k != "time_s"}
    assert all(not rec["reused"] and rec["files"] for rec in forked.values())


def test_other_formats_are_a_new_key(study, draws):
    spec, results = study
    res = run(spec, out=results, quiet=True, formats=("png",))
    assert sorted(draws) == sorted(FIGURES)
    assert not (results / "reuse" / "err.pdf").exists()           # the old PDFs are stale: removed
    assert _outputs(res.manifest)["figure/err"]["changed"] == []  # the PNG came out the same


# -- subprocesses: what a cached run imports; python -m morsuite ---------------
def _python(*args, cwd=None):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, env=env, cwd=cwd, timeout=300)


HEAVY = ("matplotlib", "pandas", "control", "dask", "scipy.sparse", "morsuite.models", "morsuite.reducers")


def test_import_morsuite_is_light():
    code = f"import sys, morsuite; print([m for m in {HEAVY!r} if m in sys.modules])"
    proc = _python("-c", code)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"


def test_cached_run_imports_no_plotting_no_dask_no_model(study):
    spec, results = study
    code = ("import sys\nfrom morsuite.cli import main\n"
            f"rc = main(['run', {str(spec)!r}, '--out', {str(results)!r}, '--quiet'])\n"
            f"print(rc, [m for m in {HEAVY!r} if m in sys.modules])")
    before = _snapshot(results / "reuse")
    proc = _python("-c", code)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "0 []"
    assert _snapshot(results / "reuse") == before
    m = json.loads((results / "reuse" / "manifest.json").read_text())
    assert m["computed"] == []


def test_memo_does_not_hide_a_bad_spec(study):
    spec, results = study
    bad = spec.with_name("bad.toml")
    bad.write_text(SPEC.replace("tol = 1e-6", "tol = 7.0"))
    proc = _python("-m", "morsuite", "run", str(bad), "--out", str(results), "--quiet")
    assert proc.returncode == 2 and "tol" in proc.stderr


def test_python_m_morsuite_is_the_command_line():
    a = _python("-m", "morsuite", "list")
    b = _python("-m", "morsuite.cli", "list")
    assert a.returncode == b.returncode == 0, a.stderr
    assert a.stdout == b.stdout and "irka" in a.stdout
    h = _python("-m", "morsuite", "run", "--help")
    assert h.returncode == 0 and "--rerender" in h.stdout and h.stdout.startswith("usage: morsuite run")
