"""The "peers" benchmark: runs against pyMOR when it is installed; otherwise records why not."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from morsuite.bench import peers as bench_peers
from morsuite.bench.output import json_default, write_json


def test_peers_without_pymor_records_the_reason(tmp_path, monkeypatch):
    monkeypatch.setattr(bench_peers, "pymor_available", lambda: (False, "ImportError: no module named pymor"))
    res = bench_peers.bench_peers(True, tmp_path, echo=None)
    assert res["pymor"] == {"available": False, "reason": "ImportError: no module named pymor"}
    assert res["rows"] == [] and res["ratios"] == {}
    assert "not run" in (tmp_path / "peers.md").read_text()
    assert (tmp_path / "peers.png").stat().st_size > 0
    json.dumps(res, default=json_default)


def test_peers_quick_against_pymor(tmp_path):
    pytest.importorskip("pymor")
    res = bench_peers.bench_peers(True, tmp_path, echo=None)
    for name in ("peers.csv", "peers.md", "peers.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    df = pd.read_csv(tmp_path / "peers.csv")
    assert set(df["peer"]) == {"pymor-irka-fo", "pymor-sor-irka", "pymor-sobt-v"}
    assert np.all(np.isfinite(df["ours_time_s"])) and np.all(np.isfinite(df["ours_error"]))
    ran = df[df["peer_time_s"].notna()]
    assert len(ran) == 5 and np.all(np.isfinite(ran["time_ratio"]))
    # pyMOR's first-order IRKA also against irka-fo with as many states (2r), with exact H2 errors
    fo = df[df["ours"] == "irka-fo"]
    assert len(fo) == 1 and fo["ours_states"].iloc[0] == 2 * fo["r"].iloc[0]
    assert np.isfinite(fo["ours_h2_error"].iloc[0]) and np.isfinite(fo["peer_h2_error"].iloc[0])
    # the same SOR-IRKA run against so-h2 at r (2r states), with its exact H2 error
    so = df[df["ours"] == "so-h2"]
    assert len(so) == 1 and so["ours_states"].iloc[0] == 2 * so["r"].iloc[0]
    assert so["peer"].iloc[0] == "pymor-sor-irka" and np.isfinite(so["ours_h2_error"].iloc[0])
    assert all(np.isfinite(r["value"]) for r in res["ratios"].values())
    # same transfer function: the dense projected model the peers use matches the full one
    assert res["models"]["dsms:g=60"]["projected_model_rel_difference"] < 1e-10
    write_json(tmp_path / "peers.json", res)
    bench_peers.rewrite(tmp_path)
    assert json.loads((tmp_path / "peers.json").read_text())["ratios"].keys() == res["ratios"].keys()
