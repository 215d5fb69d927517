"""The ``modes`` scene of a comparison (issue 35): the full model's eigenfrequencies against a dense
reference, the MAC of a modal reduced model on its own modes, the structure checks, and the page."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import scipy.linalg as sla

import morsuite as ms
from morsuite.cli import main

#: one `morsuite compare` run of five methods serves every test here (6 s of CPU): the slow set
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def compared(tmp_path_factory):
    out = tmp_path_factory.mktemp("cmp") / "out"
    rc = main(["compare", "dsms:g=40", "--states", "8", "--methods", "modal", "krylov", "bt", "irka", "so-h2",
               "--out", str(out), "--quiet"])
    assert rc == 0
    return out / "compare_dsms_g40"


def _dense_poles(fom):
    """The constrained quadratic problem's poles by the null space of G and a dense companion pencil."""
    Z = sla.null_space(fom.G.toarray())
    M, D, K = (Z.T @ X.toarray() @ Z for X in (fom.M, fom.D, fom.K))
    k = M.shape[0]
    A = np.block([[np.zeros((k, k)), np.eye(k)], [-np.linalg.solve(M, K), -np.linalg.solve(M, D)]])
    lam = np.linalg.eigvals(A)
    return lam[lam.imag >= 0]


def test_full_frequencies_agree_with_a_dense_reference(compared):
    fom = ms.models.dsms(g=40)
    ref = _dense_poles(fom)
    modes = pd.read_csv(compared / "modes_8.csv")
    full = modes["full_frequency"].dropna().unique()
    assert full.size > 0
    for w in full:   # each reported frequency is one of the model's, matched by distance (not by order)
        assert np.min(np.abs(np.abs(ref) - w)) <= 1e-8 * w
    damping = modes.dropna(subset=["full_frequency"]).drop_duplicates("full_frequency")
    for w, z in zip(damping.full_frequency, damping.full_damping):
        lam = ref[np.argmin(np.abs(np.abs(ref) - w))]
        assert z == pytest.approx(-lam.real / abs(lam), abs=1e-8)


def test_modal_reduced_model_keeps_its_own_modes_with_mac_one(compared):
    """D = 2.5 K on the DSMS: the undamped modes are the damped ones, so the modal model's modes are the
    model's exactly (frequency and shape)."""
    modes = pd.read_csv(compared / "modes_8.csv")
    modal = modes[(modes.method == "modal") & (modes.status == "matched")]
    own = modal[modal.rel_frequency_error < 1e-8]   # r = 4: three modes and the static response (m = 1)
    assert len(own) == 3
    assert (np.abs(own.mac - 1) < 1e-8).all()
    # the static correction's Ritz pair is no mode of the model: matched loosely, and its MAC says so
    assert (modal.drop(own.index).mac < 0.9).all()
    # a method without a lift V (so-h2: no projection) has no MAC: the table says so rather than inventing
    # one; the projection methods have one on every matched mode, a MAC in [0, 1]
    assert modes[modes.method == "so-h2"].mac.isna().all()
    for m in ("irka", "bt", "krylov"):
        mac = modes[(modes.method == m) & (modes.status == "matched")].mac
        assert mac.notna().all() and ((mac >= 0) & (mac <= 1 + 1e-12)).all()


def test_structure_checks_of_each_reduced_model(compared):
    s = pd.read_csv(compared / "modes_8_structure.csv").set_index("method")
    for m in ("modal", "krylov"):   # congruence: SPD M_r, K_r, PSD D_r, stable, with a lift
        assert s.loc[m, ["symmetric", "M_spd", "K_spd", "D_psd", "stable", "lift"]].astype(bool).all()
    assert pd.isna(s.loc["bt", "M_spd"]) and bool(s.loc["bt", "stable"])   # first order: no M_r to check
    rom = ms.reducers.make("irka", ms.models.dsms(g=40)).reduce(4).rom
    sym = np.linalg.norm(rom.K - rom.K.T, 1) <= 1e-10 * np.linalg.norm(rom.K, 1)
    assert bool(s.loc["irka", "symmetric"]) == bool(sym and np.allclose(rom.M, rom.M.T, rtol=0,
                                                                          atol=1e-10 * np.abs(rom.M).max()))


def test_the_page_shows_the_modes_section(compared):
    html = (compared / "index.html").read_text(encoding="utf-8")
    assert 'class="modes"' in html
    rows = pd.read_csv(compared / "modes_8.csv")
    for w in rows.full_frequency.dropna().unique()[:3]:
        assert f"{w:.4g}" in html


def test_the_first_screen_says_which_models_keep_the_modes(compared):
    """The line under the scoreboard (before the figures) counts, per method, the matched modes and those with
    MAC >= 0.9, from the same data as the structure table and the modes table."""
    html = (compared / "index.html").read_text(encoding="utf-8")
    start = html.index('<p class="glance">')
    assert start < html.index('id="figures"')
    line = html[start:html.index("</p>", start)]
    s = pd.read_csv(compared / "modes_8_structure.csv").set_index("method")
    modes = pd.read_csv(compared / "modes_8.csv")
    for m in ("modal", "krylov", "bt", "irka"):
        mac = modes[(modes.method == m) & (modes.status == "matched")].mac
        if len(mac) == int(s.loc[m, "matched"]):  # every matched mode shown in the table: count it from there
            assert int(s.loc[m, "mac_kept"]) == int((mac >= 0.9).sum())
        assert (f"{m} (r = {int(s.loc[m, 'r'])}): {int(s.loc[m, 'matched'])} matched, MAC ≥ 0.9 on "
                f"{int(s.loc[m, 'mac_kept'])}, {int(s.loc[m, 'spurious'])} spurious") in line
    assert f"so_h2 (r = {int(s.loc['so_h2', 'r'])}): " in line and "no lift, no MAC" in line
    assert "Structure kept: " in line and "modal" in line.split("Structure kept: ")[1]


def test_a_cached_rerun_takes_the_modes_from_the_cache(compared, monkeypatch):
    """A second run of the same study reads the modes data from the cache (no eigensolve: a cached re-run
    stays cheap) and writes the same tables and the same line at a glance."""
    import morsuite.analysis.modes as am

    before = [(compared / f).read_text() for f in ("modes_8.csv", "modes_8_structure.csv")]
    glance = lambda: (compared / "index.html").read_text(encoding="utf-8").split('<p class="glance">')[1].split("</p>")[0]
    line = glance()

    def no_eigensolve(*args, **kwargs):
        raise AssertionError("the modes were recomputed")
    monkeypatch.setattr(am, "model_modes", no_eigensolve)
    ms.studies.run(compared / "compare_dsms_g40.toml", out=compared.parent, quiet=True, jobs=1)
    assert [(compared / f).read_text() for f in ("modes_8.csv", "modes_8_structure.csv")] == before
    assert glance() == line
