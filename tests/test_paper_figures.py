"""The paper's figure data ship with the repository (studies/paper_figures/, issue 47 item 7): the paper
studies, validated from a copy of the repository's ``studies/`` folder alone (no ``../shared`` beside it),
find every overlay curve, and each curve is the paper's figure data: 500 samples of (omega, value) inside
its scene's frequency band, positive and finite (the paper's figures plot sigma_max and errors on log axes).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from morsuite.studies import load_spec
from morsuite.studies.scenes import _paper_curves

ROOT = Path(__file__).resolve().parents[1]

#: the curves of the paper's Figures 1-3 that the paper studies overlay (studies/paper_figures/README.md)
PAPER_CURVES = 12


def test_paper_studies_find_every_overlay_in_a_copy_of_the_repository(tmp_path):
    repo = tmp_path / "clone"
    shutil.copytree(ROOT / "studies", repo / "studies")
    assert not (tmp_path / "shared").exists()  # nothing outside the copy to fall back on
    found, used = 0, set()
    for spec in sorted((repo / "studies").glob("paper_*.toml")):
        study = load_spec(spec)
        for scene in study.scenes:
            if not scene.paper:
                continue
            notes = []
            curves = _paper_curves(scene, study, "omega", notes)  # the overlay lookup of the scene's figure
            assert notes == [] and len(curves) == len(scene.paper), (spec.name, scene.name, notes)
            grid = study.grids[scene.grid]
            band = grid.band if grid.band is not None else study.models[scene.model].band
            for curve, path in scene.paper.items():
                assert path.resolve().is_relative_to(repo), path
                data = pd.read_csv(path)
                omega, value = data["omega"].to_numpy(float), data["value"].to_numpy(float)
                assert list(data.columns) == ["omega", "value"] and omega.size == 500
                assert np.all(np.diff(omega) > 0) and band[0] * (1 - 1e-9) <= omega[0] \
                    and omega[-1] <= band[1] * (1 + 1e-9), (path.name, omega[[0, -1]], band)
                assert np.all(np.isfinite(value)) and np.all(value > 0), path.name
                found += 1
                used.add(path.name)
    assert found == PAPER_CURVES
    # every shipped curve is overlaid by a study, and no more ship
    assert used == {p.name for p in (ROOT / "studies" / "paper_figures").glob("*.csv")}
