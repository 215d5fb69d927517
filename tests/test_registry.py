"""The reducers' registry (issue 47, item 1): reducers describe themselves and register by presence.

- every registered reducer of the package declares its own description, lives in a family folder
  and says how many first-order states one unit of r gives: checked against the reduced model each
  method returns (the independent reference);
- the methods that ``morsuite compare`` offered from its own hand-written table before the registry
  (labels, reducers, options, states per order, defaults; kept here as data) are the registry's;
- a family folder that appears under ``morsuite/reducers/`` is found, registered and offered by
  compare with its variants, nothing else edited; a plugin registers through the entry-point group.
"""

from __future__ import annotations

import sys
import textwrap
import warnings

import pytest

import morsuite as ms
from morsuite.errors import OptionError
from morsuite.reducers import registry
from morsuite.reducers.options import top_level

#: compare's METHODS table as it was written by hand before the registry (2026-12-01)
OLD_TABLE = {
    "irka": ("irka", {}, 2, "IRKA (paper, second-order)"),
    "irka-fo": ("irka-fo", {}, 1, "irka-fo (first-order IRKA)"),
    "so-h2": ("so-h2", {}, 2, "so-h2 (second-order H2 descent)"),
    "bt": ("bt", {}, 1, "BT, first-order"),
    "irka-projected": ("irka-projected", {}, 2, "IRKA, Pi-projected (dense)"),
    **{f"bt-{lvl}": ("bt", {"form": lvl}, 2, f"BT ({lvl}, second-order)") for lvl in ("pp", "pv", "vp", "vv", "fv")},
    "bt-fl": ("bt-fl", {"limited": "controllability"}, 1, "BT, frequency-limited to the band (one-sided: stable)"),
    "modal": ("modal", {}, 2, "modal truncation + static correction"),
    "krylov": ("krylov", {}, 2, "Krylov moment matching (SOAR)"),
}
OLD_DEFAULTS = ("irka", "irka-fo", "so-h2", "bt-vv", "bt", "modal", "krylov")


def _package_reducers():
    return [n for n in ms.reducers.available() if ms.reducers.get_class(n).__module__.startswith("morsuite.")]


def test_every_reducer_describes_itself_in_its_family_folder():
    families = set(registry.families())
    for name in _package_reducers():
        cls = ms.reducers.get_class(name)
        assert isinstance(vars(cls).get("DESCRIPTION"), ms.reducers.Description), name
        desc = ms.reducers.describe(name)
        assert desc.family in families and cls.__module__.startswith(f"morsuite.reducers.{desc.family}.")
        assert desc.label and desc.targets and desc.cost and desc.use_for, name
        # the options users set are top-level ones (not in an advanced group), and few
        assert set(desc.options) <= set(top_level(cls.OPTIONS, cls.GROUPS)) and len(desc.options) <= 12, name


def test_states_per_order_is_what_each_method_returns():
    fom = ms.models.dsms(g=20)
    for name, m in ms.reducers.methods().items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            red = ms.reducers.make(m.reducer, fom, **m.options)
            res = red.reduce(2)
        assert res.info["states"] == m.states_per_order * res.info["r"], name
        assert res.rom.kind == m.result and red.states_per_order() == m.states_per_order, name


def test_compare_offers_what_its_table_held():
    from morsuite.studies.compare import all_methods, default_methods

    offered = all_methods()
    assert set(OLD_TABLE) <= set(offered)
    for name, (reducer, options, spo, label) in OLD_TABLE.items():
        m = offered[name]
        cls = ms.reducers.get_class(reducer)
        full = {k: o.validate(reducer, k, {**m.options}.get(k, o.default)) for k, o in cls.OPTIONS.items()}
        old = {k: o.validate(reducer, k, options.get(k, o.default)) for k, o in cls.OPTIONS.items()}
        assert (m.reducer, m.states_per_order, m.label) == (reducer, spo, label) and full == old, name
    # the old defaults in their order, then the two of issue 46 (item 4: in compare by default)
    assert default_methods() == OLD_DEFAULTS + ("adaptive", "dominant")


def test_a_variant_must_fit_its_reducer(monkeypatch):
    from dataclasses import replace

    from morsuite.reducers.modal.reducer import Modal

    bad = replace(Modal.DESCRIPTION, variants=(ms.reducers.Variant("modal-x", {"nope": 1}, "x"),))
    monkeypatch.setattr(Modal, "DESCRIPTION", bad)
    with pytest.raises(OptionError, match=r"variant 'modal-x': Modal got unknown option\(s\) 'nope'"):
        ms.reducers.methods()
    taken = replace(Modal.DESCRIPTION, variants=(ms.reducers.Variant("krylov", {}, "x"),))
    monkeypatch.setattr(Modal, "DESCRIPTION", taken)
    with pytest.raises(OptionError, match="variant 'krylov' of reducer 'modal': the name is taken"):
        ms.reducers.methods()
    with pytest.raises(OptionError, match="Description.result must be one of"):
        ms.reducers.Description(label="x", result="third-order")


TOY = '''
"""A toy family: modal truncation under another name, with a variant."""
from morsuite.reducers.modal.reducer import Modal
from morsuite.reducers.registry import Description, Variant


class Toy(Modal):
    """Modal truncation called toy."""

    name = "toy"
    DESCRIPTION = Description(label="toy modal", result="second-order", targets="t", cost="c", use_for="u",
                              options=("selection",),
                              variants=(Variant("toy-band", {"selection": "band"}, "toy modal in the band"),))
'''


@pytest.fixture
def toy_family(tmp_path, monkeypatch):
    """A family folder ``toyfam`` on the reducers' package path, discovered afresh; forgotten after."""
    import morsuite.reducers as pkg

    (tmp_path / "toyfam").mkdir()
    (tmp_path / "toyfam" / "__init__.py").write_text('"""Toys."""\n')
    (tmp_path / "toyfam" / "toy.py").write_text(textwrap.dedent(TOY))
    monkeypatch.setattr(pkg, "__path__", list(pkg.__path__) + [str(tmp_path)])
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(registry, "_FAMILY", dict(registry._FAMILY))
    monkeypatch.setattr(registry, "_DISCOVERED", False)
    yield
    for mod in [m for m in sys.modules if m.startswith("morsuite.reducers.toyfam")]:
        del sys.modules[mod]


def test_a_family_folder_just_works(toy_family, tmp_path):
    from morsuite.studies.compare import all_methods, compare_spec

    assert "toyfam" in registry.families() and "toy" in ms.reducers.available()
    assert ms.reducers.describe("toy").family == "toyfam"
    assert ms.reducers.Toy is ms.reducers.get_class("toy")
    offered = all_methods()
    assert offered["toy-band"].reducer == "toy" and offered["toy-band"].options == {"selection": "band"}
    assert not offered["toy"].default  # not among compare's defaults unless it says so
    spec = compare_spec("dsms:g=40", states=[8], methods=["toy", "toy-band", "bt"])
    assert spec["methods"]["toy_band"] == {"reducer": "toy", "options": {"selection": "band"},
                                           "label": "toy modal in the band"}
    table = next(s for s in spec["scenes"] if s["kind"] == "table")
    assert table["r"] == 4 and table["r_by_method"] == {"bt": 8}  # toy is second-order: 8 states at r = 4
    fom = ms.models.dsms(g=40)
    ref = ms.reducers.make("modal", fom, selection="band").reduce(4).rom
    got = ms.reducers.make("toy", fom, selection="band").reduce(4).rom
    w = ms.analysis.freq_grid(fom.band, 20)
    assert abs(got.freqresp(w) - ref.freqresp(w)).max() == 0.0  # the same computation under its new name


def test_plugin_through_entry_point(monkeypatch):
    with pytest.raises(OptionError, match="unknown reducer 'nope'.*available"):
        ms.reducers.make("nope", ms.models.dsms(50))

    class Plugin(ms.reducers.IRKA):
        name = "plugin-irka"

    class EP:
        name = "plugin-irka"

        def load(self):
            return Plugin

    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(registry, "_ENTRY_POINTS_LOADED", False)
    monkeypatch.setattr("importlib.metadata.entry_points",
                        lambda group=None: [EP()] if group == "morsuite.reducers" else [])
    assert "plugin-irka" in ms.reducers.available()
    assert isinstance(ms.reducers.make("plugin-irka", ms.models.dsms(50)), Plugin)
    desc = ms.reducers.describe("plugin-irka")  # derived: no description of its own, no inherited variants
    assert desc.label == "plugin-irka" and desc.result == "second-order" and desc.variants == ()
    assert ms.reducers.methods()["plugin-irka"].states_per_order == 2


def test_reducer_table_of_the_docs_lists_every_registered_reducer():
    """Item 3: the table of docs/design/reducers.md is generated from the registry (its directive), one
    row per registered reducer with its variants; each description's page exists."""
    import importlib.util
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    sys.path.insert(0, str(root / "docs" / "_ext"))
    try:
        spec = importlib.util.spec_from_file_location("morsuite_tables", root / "docs" / "_ext" / "morsuite_tables.py")
        tables = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(tables)
    finally:
        sys.path.pop(0)
    rows = tables.reducer_table_rows()
    listed = [r[0].split("``")[1] for r in rows]
    assert sorted(listed) == ms.reducers.available()
    for name, m in ms.reducers.methods().items():
        if m.name != m.reducer:  # a variant: named in its reducer's row
            assert f"``{name}``" in rows[listed.index(m.reducer)][1]
    page = (root / "docs" / "design" / "reducers.md").read_text()
    section = page.split("## Which reducer for what")[1].split("\n## ")[0]
    assert ".. morsuite-reducer-table::" in section and "|---" not in section  # generated, not by hand
    for name in _package_reducers():
        assert (root / "docs" / "design" / f"{ms.reducers.describe(name).page}.md").is_file(), name
