"""The table of refused inputs: one row per input the suite refuses, with its error and message.

Used by ``test_refused_inputs.py`` (one test per row) and by
``refused_table.py``, which runs every row and prints the Markdown table of
the README section "Refused inputs" with the actual messages.

Each row: ``(key, area, input, call, error class, message regex)``; ``call``
takes a scratch directory (``pathlib.Path``) and must raise.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import scipy.io as sio
import scipy.sparse as sp

import morsuite as ms
from morsuite.errors import (FileFormatError, InputError, MemoryBudgetError, ModelError, OptionError,
                             ShapeError, SingularShiftError, SpecError)

DATA = Path(__file__).resolve().parents[1] / "data"


def parts():
    """Consistent (M, D, K, G, F, L) of a 6-mass chain with one constraint."""
    n1 = 6
    M = sp.identity(n1, format="csr") * 2.0
    K = sp.diags([-np.ones(n1 - 1), 3 * np.ones(n1), -np.ones(n1 - 1)], [-1, 0, 1], format="csr")
    G = sp.csr_matrix(([1.0, -1.0], ([0, 0], [0, n1 - 1])), shape=(1, n1))
    F = np.zeros((n1, 1))
    F[0, 0] = 1.0
    L = np.zeros((2, n1))
    L[0, 1] = L[1, 2] = 1.0
    return dict(M=M, D=0.1 * K, K=K, G=G, F=F, L=L)


def model(**replace):
    p = parts()
    p.update(replace)
    kw = {k: p.pop(k) for k in ("band",) if k in p}
    return ms.models.Index3Model(p["M"], p["D"], p["K"], p["G"], p["F"], p["L"], **kw)


def small():
    return ms.models.dsms(20)


def irka(**options):
    return ms.reducers.make("irka", small(), **options)


SPEC = {"name": "t", "models": {"d": "dsms:g=20"}, "methods": {"irka": {}},
        "scenes": [{"name": "s", "kind": "error", "model": "d", "r": 2}]}


def spec(**edit):
    """A copy of a minimal valid study dict with top-level or scene keys replaced (``scene_*``)."""
    from morsuite.studies.spec import study_from_dict

    data = copy.deepcopy(SPEC)
    for k, v in edit.items():
        if k.startswith("scene_"):
            data["scenes"][0][k[6:]] = v
        else:
            data[k] = v
    return study_from_dict(data)


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _mat_without(tmp: Path, key: str) -> Path:
    raw = sio.loadmat(str(DATA / "mess_msd_ind3_g600.mat"))
    data = {k: v for k, v in raw.items() if not k.startswith("__") and k != key}
    out = tmp / f"no{key}.mat"
    sio.savemat(str(out), data)
    return out


def _npz_without(tmp: Path, key: str) -> Path:
    out = tmp / "m.npz"
    ms.models.save_npz(small(), out)
    with np.load(out, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files if k != key}
    bad = tmp / f"no_{key}.npz"
    np.savez(bad, **data)
    return bad


def _pole_model():
    n1 = 4
    K = sp.diags([-1.0, 2.0, 2.0, 2.0], format="csr")
    G = sp.csr_matrix(([1.0, -1.0], ([0, 0], [1, 3])), shape=(1, n1))
    F = np.ones((n1, 1))
    return ms.models.Index3Model(sp.identity(n1), sp.csr_matrix((n1, n1)), K, G, F, F.T)


def _lradi():
    import importlib
    return importlib.import_module("morsuite.linalg.lradi").lradi


# (key, area, input, call(tmp), error class, message regex)
CASES = [
    # -- model matrices ------------------------------------------------------------
    ("M-missing", "matrix", "M is None", lambda t: model(M=None), InputError, r"matrix M is missing"),
    ("M-not-square", "matrix", "M of shape (6, 5)", lambda t: model(M=sp.random(6, 5, 0.5, format="csr")),
     ShapeError, r"matrix M must be square"),
    ("M-empty", "matrix", "M of shape (0, 0)", lambda t: ms.models.Index3Model(
        np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0)), None, np.zeros((0, 1)), np.zeros((1, 0))),
     ShapeError, r"matrix M is empty"),
    ("D-shape", "matrix", "D not n1 x n1", lambda t: model(D=sp.identity(5)), ShapeError,
     r"matrix D has shape \(5, 5\); expected \(6, 6\)"),
    ("K-shape", "matrix", "K not n1 x n1", lambda t: model(K=sp.identity(7)), ShapeError, r"matrix K has shape"),
    ("G-columns", "matrix", "G with n1 - 1 columns", lambda t: model(G=sp.csr_matrix(np.ones((1, 5)))),
     ShapeError, r"matrix G has 5 columns; expected n1 = 6"),
    ("G-too-many-rows", "matrix", "n2 >= n1", lambda t: model(G=sp.identity(6, format="csr")), ShapeError,
     r"matrix G has n2 = 6 rows; expected n2 < n1"),
    ("F-rows", "matrix", "F with n1 - 1 rows", lambda t: model(F=np.ones((5, 1))), ShapeError,
     r"matrix F has 5 rows; expected n1 = 6"),
    ("L-columns", "matrix", "L with n1 + 1 columns", lambda t: model(L=np.ones((1, 7))), ShapeError,
     r"matrix L has 7 columns; expected n1 = 6"),
    ("F-no-columns", "matrix", "F of shape (n1, 0)", lambda t: model(F=np.zeros((6, 0))), ShapeError,
     r"at least one input and one output"),
    ("K-nan", "matrix", "NaN entry in K", lambda t: model(K=parts()["K"] * np.nan), InputError,
     r"matrix K has non-finite entries"),
    ("F-inf", "matrix", "inf entry in F", lambda t: model(F=np.full((6, 1), np.inf)), InputError,
     r"matrix F has non-finite entries"),
    ("K-complex", "matrix", "complex K (nonzero imaginary part)", lambda t: model(K=parts()["K"] * (1 + 1j)),
     InputError, r"matrix K is complex with a nonzero imaginary part"),
    ("F-object", "matrix", "F of dtype object", lambda t: model(F=np.array([[None]] * 6)), InputError,
     r"matrix F has dtype object"),
    ("L-strings", "matrix", "L of strings", lambda t: model(L=np.array([["a"] * 6])), InputError,
     r"matrix L has non-numeric dtype"),
    ("M-ragged", "matrix", "M as a ragged nested list", lambda t: model(M=[[1.0, 2.0], [3.0]]), InputError,
     r"matrix M is not a rectangular array"),
    ("M-3d", "matrix", "M with 3 dimensions", lambda t: model(M=np.ones((6, 6, 1))), ShapeError,
     r"matrix M must be 2-D"),
    ("G-zero-row", "matrix", "a zero row in G", lambda t: model(G=sp.csr_matrix(np.vstack([
        parts()["G"].toarray(), np.zeros((1, 6))]))), ModelError, r"matrix G has zero rows \[1\]"),
    ("G-rank", "matrix", "G with two equal rows", lambda t: model(G=sp.csr_matrix(np.vstack([
        parts()["G"].toarray()] * 2))), ModelError, r"matrix G is numerically rank deficient"),
    ("M-singular", "matrix", "singular M with constraints", lambda t: model(M=sp.diags([1.0, 1, 1, 1, 1, 0])),
     ModelError, r"matrix M is singular; the constraint check needs M\^-1"),
    ("band-order", "model", "band = (1, 0.1)", lambda t: model(band=(1.0, 0.1)), InputError,
     r"band must satisfy 0 < lo < hi < inf"),
    ("band-pair", "model", "band = 5", lambda t: model(band=5), InputError, r"band must be a pair"),
    # -- evaluation ---------------------------------------------------------------------
    ("s-nan", "argument", "transfer(nan)", lambda t: small().transfer(np.nan), InputError,
     r"s must be finite"),
    ("s-text", "argument", "transfer('1j')", lambda t: small().transfer("x"), InputError,
     r"s must be a scalar number"),
    ("omega-empty", "argument", "freqresp([])", lambda t: small().freqresp([]), InputError,
     r"omega must be a non-empty 1-D array"),
    ("omega-complex", "argument", "freqresp([1j])", lambda t: small().freqresp([1j]), InputError,
     r"omega must be real"),
    ("omega-nan", "argument", "freqresp([nan])", lambda t: small().freqresp([np.nan]), InputError,
     r"omega has non-finite entries"),
    ("s-pole", "argument", "transfer(s) at a pole", lambda t: _pole_model().transfer(1.0), SingularShiftError,
     r"exactly singular: the shift is a pole"),
    ("coeffs-nan", "argument", "SaddlePointSolver.factor(coeffs=(nan, 0, 1))",
     lambda t: small().new_solver().factor(coeffs=(np.nan, 0.0, 1.0)), InputError, r"coeffs must be finite"),
    ("rhs-rows", "argument", "SaddleLU.solve with a wrong number of rows",
     lambda t: small().new_solver().factor(1j).solve(np.ones(3)), InputError, r"rhs has 3 rows"),
    # -- generators and the catalog --------------------------------------------------------------
    ("dsms-g", "generator", "dsms(g=3)", lambda t: ms.models.dsms(3), InputError, r"g must be finite and >= 4"),
    ("tcom-odd", "generator", "tcom(nc=5) constrained", lambda t: ms.models.tcom(5), InputError,
     r"nc must be even for the constrained TCOM"),
    ("random-n2", "generator", "random_constrained(n1=10, n2=6)",
     lambda t: ms.models.random_constrained(n1=10, n2=6), InputError, r"n2 must be an integer in \[0, 5\]"),
    ("random-damping", "generator", "random_constrained(damping='viscous')",
     lambda t: ms.models.random_constrained(damping="viscous"), InputError, r"damping must be one of"),
    ("random-spread", "generator", "random_constrained(mass_spread=20)",
     lambda t: ms.models.random_constrained(mass_spread=20), InputError, r"mass_spread must be finite and in"),
    ("random-unit", "generator", "random_constrained(stiffness_unit=-1)",
     lambda t: ms.models.random_constrained(stiffness_unit=-1.0), InputError,
     r"stiffness_unit must be finite and in \(0"),
    ("catalog-name", "model spec", "'nope:g=3'", lambda t: ms.models.parse("nope:g=3"), InputError,
     r"unknown model 'nope'; available: dsms, random, tcom"),
    ("catalog-param", "model spec", "'dsms:h=3'", lambda t: ms.models.parse("dsms:h=3"), InputError,
     r"model 'dsms' has no parameter 'h'"),
    ("catalog-syntax", "model spec", "'dsms:g'", lambda t: ms.models.parse("dsms:g"), InputError,
     r"expected key=value, got 'g'"),
    # -- files ---------------------------------------------------------------------------------------
    ("file-missing", "file", "load('nothing.npz')", lambda t: ms.models.load(t / "nothing.npz"),
     FileFormatError, r"does not exist or is not a file"),
    ("file-extension", "file", "load('model.txt')", lambda t: ms.models.load(_write(t / "model.txt", "x")),
     FileFormatError, r"unknown extension '\.txt'; expected \.mat or \.npz"),
    ("npz-corrupt", "file", "a .npz that is not a zip", lambda t: ms.models.load(_write(t / "bad.npz", "junk")),
     FileFormatError, r"not a readable npz file"),
    ("npz-key", "file", ".npz without F", lambda t: ms.models.load(_npz_without(t, "F")), FileFormatError,
     r"missing key F"),
    ("npz-format", "file", ".npz without the format tag", lambda t: ms.models.load(_npz_without(t, "format")),
     FileFormatError, r"entry 'format' is missing"),
    ("mat-corrupt", "file", "a .mat that is not MATLAB", lambda t: ms.models.load(_write(t / "bad.mat", "junk")),
     FileFormatError, r"not a readable \.mat file"),
    ("mat-G", "file", ".mat without G", lambda t: ms.models.load(_mat_without(t, "G")), FileFormatError,
     r"missing matrix G"),
    ("mat-sign", "file", "M.E.S.S. file read with sign='physical'",
     lambda t: ms.models.load_mat(DATA / "mess_msd_ind3_g600.mat", sign="physical"), FileFormatError,
     r"does not follow the sign='physical' convention"),
    ("mat-sign-option", "option", "load_mat(sign='negative')",
     lambda t: ms.models.load_mat(DATA / "mess_msd_ind3_g600.mat", sign="negative"), InputError,
     r"sign must be 'mess' or 'physical'"),
    ("save-non-model", "argument", "save_npz(a dict)", lambda t: ms.models.save_npz({}, t / "x.npz"),
     InputError, r"model must be an Index3Model; got dict"),
    ("rom-missing", "file", "load_rom('none.npz')", lambda t: ms.rom.load_rom(t / "none.npz"),
     FileFormatError, r"ROM file .* does not exist"),
    ("rom-kind", "file", "ROM .npz without 'kind'",
     lambda t: ms.rom.load_rom((np.savez(t / "r.npz", M=np.eye(1)), t / "r.npz")[1]),
     FileFormatError, r"entry 'kind' missing or unknown"),
    ("rom-extension", "argument", "rom.save('rom.txt')",
     lambda t: ms.rom.SecondOrderROM(np.eye(1), np.eye(1), np.eye(1), np.ones(1), np.ones(1)).save(t / "r.txt"),
     InputError, r"extension must be \.npz or \.mat"),
    # -- reducers: names, options, r ----------------------------------------------------------------
    ("reducer-name", "option", "make('irk', fom)", lambda t: ms.reducers.make("irk", small()), OptionError,
     r"unknown reducer 'irk'; available: .*irka"),
    ("reducer-fom", "argument", "make('irka', a matrix)", lambda t: ms.reducers.make("irka", np.eye(3)),
     InputError, r"fom must be an Index3Model"),
    ("option-unknown", "option", "irka(tolerance=1e-6)", lambda t: irka(tolerance=1e-6), OptionError,
     r"IRKA got unknown option\(s\) 'tolerance'; valid options: .*tol"),
    ("option-tol", "option", "irka(tol=-1)", lambda t: irka(tol=-1), OptionError,
     r"The 'tol' parameter of IRKA must be a float in \(0, 1\)\. Got -1 instead\."),
    ("option-maxit", "option", "irka(maxit=0)", lambda t: irka(maxit=0), OptionError,
     r"The 'maxit' parameter of IRKA must be an int in \[1, inf\)"),
    ("option-bool", "option", "irka(maxit=True)", lambda t: irka(maxit=True), OptionError,
     r"The 'maxit' parameter of IRKA must be an int"),
    ("option-choice", "option", "irka(update='newton')", lambda t: irka(update="newton"), OptionError,
     r"The 'update' parameter of IRKA must be one of 'auto', 'bt', 'residue'"),
    ("option-nan-shift", "option", "irka(init='given', init_shifts=[nan])",
     lambda t: irka(init="given", init_shifts=[np.nan]), OptionError,
     r"The 'init_shifts' parameter of IRKA must be an array of numbers"),
    ("given-missing", "option", "irka(init='given') without init_shifts", lambda t: irka(init="given"),
     InputError, r"init='given' needs the option init_shifts"),
    ("given-unused", "option", "irka(init_shifts=[1.0]) with init='logspace'", lambda t: irka(init_shifts=[1.0]),
     InputError, r"only used with init='given'"),
    ("given-lhp", "option", "init_shifts in the left half-plane",
     lambda t: irka(init="given", init_shifts=[-1.0, 0.5]).reduce(2), InputError,
     r"init_shifts must lie in the open right half-plane"),
    ("given-imag-axis", "option", "init_shifts on the imaginary axis",
     lambda t: irka(init="given", init_shifts=[1j, -1j]).reduce(2), InputError,
     r"init_shifts must lie in the open right half-plane"),
    ("given-conjugate", "option", "init_shifts not closed under conjugation",
     lambda t: irka(init="given", init_shifts=[1 + 1j, 2.0]).reduce(2), InputError,
     r"init_shifts must be closed under complex conjugation"),
    ("r-zero", "argument", "reduce(0)", lambda t: irka().reduce(0), InputError, r"r must be a positive integer; got 0"),
    ("r-float", "argument", "reduce(2.5)", lambda t: irka().reduce(2.5), InputError,
     r"r must be a positive integer; got 2\.5"),
    ("r-bool", "argument", "reduce(True)", lambda t: irka().reduce(True), InputError,
     r"r must be a positive integer; got True"),
    ("r-order", "argument", "reduce(r) with r > n1 - n2", lambda t: irka().reduce(20), InputError,
     r"r = 20 exceeds the order of the full model on its hidden manifold \(n1 - n2 = 19\)"),
    ("projected-memory", "option", "irka-projected over its memory budget",
     lambda t: ms.reducers.make("irka-projected", ms.models.dsms(2000), memory_budget_gib=0.01), MemoryBudgetError,
     r"would need about .* GiB .* above the budget memory_budget_gib = 0\.01"),
    # -- reduced models and analysis -----------------------------------------------------------------
    ("rom-nan", "matrix", "SecondOrderROM with a NaN in K",
     lambda t: ms.rom.SecondOrderROM(np.eye(2), np.eye(2), np.full((2, 2), np.nan), np.ones(2), np.ones(2)),
     InputError, r"matrix K has non-finite entries"),
    ("rom-shape", "matrix", "SecondOrderROM with a non-square M",
     lambda t: ms.rom.SecondOrderROM(np.ones((2, 3)), np.eye(2), np.eye(2), np.ones(2), np.ones(2)),
     ShapeError, r"matrix M must be square"),
    ("grid-band", "argument", "freq_grid((1, 0.1))", lambda t: ms.analysis.freq_grid((1.0, 0.1)), InputError,
     r"band must satisfy 0 < lo < hi"),
    ("sigma-shape", "argument", "sigma_max of a 4-D array", lambda t: ms.analysis.sigma_max(np.ones((2, 2, 2, 2))),
     InputError, r"H must have shape \(k, p, m\) or \(p, m\)"),
    ("errors-H", "argument", "errors(..., H_full of the wrong length)",
     lambda t: ms.analysis.errors(small(), irka(maxit=2).reduce(2).rom, [0.1, 0.2], H_full=np.ones((3, 3, 1))),
     InputError, r"H_full has 3 frequencies; omega has 2"),
    # -- low-rank ADI ------------------------------------------------------------------------------
    ("adi-tol", "option", "lradi(tol=2)", lambda t: _lradi()(small(), tol=2.0), InputError,
     r"tol must be a float in \(0, 1\)"),
    ("adi-shifts", "option", "lradi(shifts=[1.0]) (right half-plane)", lambda t: _lradi()(small(), shifts=[1.0]),
     InputError, r"shifts must lie in the open left half-plane"),
    ("adi-equation", "option", "lradi(equation='both')", lambda t: _lradi()(small(), equation="both"),
     InputError, r"equation must be 'controllability' or 'observability'"),
    # -- study specifications ---------------------------------------------------------------------------
    ("spec-missing", "study spec", "load_spec('none.toml')",
     lambda t: __import__("morsuite.studies.spec", fromlist=["load_spec"]).load_spec(t / "none.toml"),
     SpecError, r"study spec .*none\.toml' does not exist"),
    ("spec-toml", "study spec", "a file that is not TOML",
     lambda t: __import__("morsuite.studies.spec", fromlist=["load_spec"]).load_spec(_write(t / "s.toml", "[[x")),
     SpecError, r"not valid TOML"),
    ("spec-key", "study spec", "scene key 'gird'", lambda t: spec(scene_gird="default"), SpecError,
     r"unknown key 'gird'.*did you mean 'grid'"),
    ("spec-kind", "study spec", "scene kind 'errors'", lambda t: spec(scene_kind="errors"), SpecError,
     r"unknown value 'errors'.*valid choices"),
    ("spec-model", "study spec", "model 'nope:g=3'", lambda t: spec(models={"d": "nope:g=3"}), SpecError,
     r"unknown model 'nope'"),
    ("spec-reducer", "study spec", "method with reducer 'irk'", lambda t: spec(methods={"irka": {"reducer": "irk"}}),
     SpecError, r"unknown reducer 'irk'"),
    ("spec-option", "study spec", "method option tol = 2", lambda t: spec(methods={"irka": {"options": {"tol": 2}}}),
     SpecError, r"The 'tol' parameter of IRKA must be a float in \(0, 1\)"),
    ("spec-r", "study spec", "r above n1 - n2", lambda t: spec(scene_r=40), SpecError,
     r"r = 40 exceeds the order n1 - n2 = 19"),
    ("spec-r-type", "study spec", "r = 'ten'", lambda t: spec(scene_r="ten"), SpecError,
     r"expected a positive integer, a list of them"),
    ("spec-name", "study spec", "name with a slash", lambda t: spec(name="a/b"), SpecError,
     r"'a/b' is not a file-name-safe string"),
]
