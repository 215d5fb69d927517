"""Every benchmark the README or docs/benchmarks.md names is registered (a documented command that fails is a
defect)."""

from __future__ import annotations

import re
from pathlib import Path

from morsuite import bench


def test_readme_benchmarks_are_registered():
    bench._discover()
    root = Path(__file__).resolve().parents[1]
    readme = "\n".join((root / name).read_text() for name in ("README.md", "docs/benchmarks.md"))
    named = set()
    for line in re.findall(r"morsuite bench ([^\n`]+)", readme):
        named.update(w for w in line.split() if not w.startswith("-") and not w.startswith("results"))
    assert named, "the README names no benchmark"
    missing = named - set(bench.BENCHMARKS)
    assert not missing, f"README names unregistered benchmarks: {sorted(missing)}"
    assert {"freqresp", "irka", "bt", "projected", "pareto", "peers", "scaling"} <= set(bench.BENCHMARKS)
