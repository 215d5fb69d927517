"""Options people can hold (issue 47, item 2): a few at the top level, the advanced ones in named groups.

- every reducer has at most 15 top-level options (those of the package at most 13), each group's members
  are declared options, no option is in two groups and no group has an option's name;
- a group's table, the flat name (as before the groups) and a study's ``[methods.X.options.GROUP]`` give
  the same validated options, recorded flat in ``info["options"]`` and in the method's cache key;
- a name given twice, an unknown name inside a group, a group given as a value and a value out of range
  inside a group are refused with messages that name the group and the option.
"""

from __future__ import annotations

import argparse

import pytest

import morsuite as ms
from morsuite.errors import OptionError, SpecError
from morsuite.reducers.options import top_level


@pytest.fixture(scope="module")
def fom():
    return ms.models.dsms(g=20)


def test_few_top_level_options_and_well_formed_groups():
    for name in ms.reducers.available():
        cls = ms.reducers.get_class(name)
        top = top_level(cls.OPTIONS, cls.GROUPS)
        assert len(top) <= (13 if cls.__module__.startswith("morsuite.") else 15), (name, top)
        members = [m for g in cls.GROUPS.values() for m in g.members]
        assert set(members) <= set(cls.OPTIONS) and len(members) == len(set(members)), name
        assert not set(cls.GROUPS) & set(cls.OPTIONS), name
        for grp in cls.GROUPS.values():  # short names are unique inside a group
            assert len(grp.names()) == len(grp.members), name


def test_a_group_and_the_flat_names_give_the_same_options(fom):
    grouped = ms.reducers.make("irka", fom, tol=1e-7, safeguards={"window": 5, "shortlist": 3},
                               stopping={"criterion": "shifts"})
    flat = ms.reducers.make("irka", fom, tol=1e-7, safeguard_window=5, shortlist=3, criterion="shifts")
    assert grouped.get_params() == flat.get_params()
    assert grouped.options["safeguard_window"] == 5 and grouped.options["criterion"] == "shifts"
    bt = ms.reducers.make("bt", fom, adi={"num_shifts": 8, "shifts": "penzl"})
    info = bt.reduce(4).info
    assert info["options"]["num_shifts"] == 8 and info["options"]["shifts"] == "penzl"  # recorded flat
    assert set(info["options"]) == set(ms.reducers.get_class("bt").OPTIONS)


def test_refusals_name_the_group_and_the_option(fom):
    with pytest.raises(OptionError, match=r"The 'safeguards' options of IRKA have no 'windw'; valid: window, "):
        ms.reducers.make("irka", fom, safeguards={"windw": 5})
    with pytest.raises(OptionError, match=r"The 'safeguards' options of IRKA are given as a table"):
        ms.reducers.make("irka", fom, safeguards=5)
    with pytest.raises(OptionError, match=r"option 'safeguard_window' is given twice, as 'safeguard_window' and "
                                          r"as 'safeguards.window'"):
        ms.reducers.make("irka", fom, safeguard_window=4, safeguards={"window": 5})
    with pytest.raises(OptionError, match=r"The 'safeguards.window' parameter of IRKA must be an int in \[2, inf\)"):
        ms.reducers.make("irka", fom, safeguards={"window": 1})
    with pytest.raises(OptionError, match=r"IRKA got unknown option\(s\) 'tolerance'; valid options: .*tol.*; "
                                          r"advanced, as tables: shift_update \(residue_hysteresis"):
        ms.reducers.make("irka", fom, tolerance=1e-6)


STUDY = """
name = "grouped"
[models]
m = "dsms:g=20"
[methods.grouped]
reducer = "so-h2"
[methods.grouped.options.adi]
num_shifts = 8
[methods.flat]
reducer = "so-h2"
options = {{ num_shifts = 8 }}
[methods.plain]
reducer = "so-h2"
[[scenes]]
name = "t"
kind = "table"
model = "m"
r = 2
{extra}
"""


def test_a_study_sets_a_group_as_a_table(tmp_path):
    from morsuite.studies.spec import load_spec

    (tmp_path / "s.toml").write_text(STUDY.format(extra=""))
    study = load_spec(tmp_path / "s.toml")
    g, f, p = (study.methods[a] for a in ("grouped", "flat", "plain"))
    assert g.full_options == f.full_options and g.full_options["num_shifts"] == 8
    assert g.method_id == f.method_id != p.method_id  # the cache key digests the flat options
    bad = STUDY.format(extra="").replace("num_shifts = 8\n[methods.flat]", "num_shift = 8\n[methods.flat]")
    (tmp_path / "bad.toml").write_text(bad)
    with pytest.raises(SpecError, match=r"methods.grouped.options: .*'adi' options of SOH2 have no 'num_shift'"):
        load_spec(tmp_path / "bad.toml")


def test_command_line_group_dot_key(fom):
    from morsuite.cli import _reduced

    args = argparse.Namespace(model="dsms:g=20", method="bt", r=4, json=True,
                              option=["adi.num_shifts=8", "tol=1e-10"])
    _, res = _reduced(args)
    assert res.info["options"]["num_shifts"] == 8 and res.info["options"]["tol"] == 1e-10
