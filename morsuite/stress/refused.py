r"""The table of refused inputs: every input the suite refuses, its error class and message.

Each row is a :class:`Refusal` ``(key, area, what, call, error, match,
needs_data)``: ``call(tmp, data)`` must raise ``error`` (a subclass of
:class:`~morsuite.errors.MorsuiteError`) with a message matching the regex
``match``; ``tmp`` is a scratch directory and ``data`` the directory holding
:data:`DATA_FILE` (the M.E.S.S. DSMS file with g = 600), used only by the rows
with ``needs_data``. Besides the rows written here, two per registered reducer of the
package are read from the registry (an unknown option; ``reduce(r)`` above its largest
order). tests/stress/test_refused_inputs.py runs one test per row;
:func:`markdown_table` runs every row and prints the table (the one in the
documentation's design note on refused inputs) with the actual messages::

    python -m morsuite.stress --refused-table [--data-dir DIR]

The data directory defaults to ``tests/data`` of the repository checkout the
package is imported from (:func:`default_data_dir`); where that file is absent
(an installed package) the rows that need it are left out of the table and
named on stderr. Running the table costs a few seconds (it builds dsms(2000)
and runs IRKA on dsms(20)).
"""

from __future__ import annotations

import sys
import tempfile
import warnings
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np
import scipy.sparse as sp

import morsuite as ms
from morsuite.linalg.eigen import constrained_modes

from ..errors import (FileFormatError, InputError, MemoryBudgetError, ModelError, OptionError, ShapeError,
                      SingularShiftError, SpecError)
from .refused_inputs import (DATA_FILE, _changed_rom_file, _hdf5, _irka, _lradi, _modal, _mat_without, _model,
                             _mtx_set, _nan_rom, _npz_without, _other_io_rom, _parts, _pole_model, _rom, _sim, _small,
                             _spec, _time_spec, _write)

__all__ = ["Refusal", "CASES", "DATA_FILE", "default_data_dir", "table_rows", "markdown_table"]

#: messages longer than this are cut in the table
MAX_MESSAGE = 160
_CHECKOUT_DATA = Path(__file__).resolve().parents[2] / "tests" / "data"


class Refusal(NamedTuple):
    """One row of the table: ``call(tmp, data)`` raises ``error`` with a message matching ``match``."""

    key: str
    area: str
    what: str
    call: Callable
    error: type
    match: str
    needs_data: bool = False


def default_data_dir() -> Path | None:
    """``tests/data`` of the repository checkout (None if it has no :data:`DATA_FILE`)."""
    return _CHECKOUT_DATA if (_CHECKOUT_DATA / DATA_FILE).is_file() else None



_ROWS = [
    # -- model matrices ------------------------------------------------------------
    ("M-missing", "matrix", "M is None", lambda t, d: _model(M=None), InputError, r"matrix M is missing"),
    ("M-not-square", "matrix", "M of shape (6, 5)", lambda t, d: _model(M=sp.random(6, 5, 0.5, format="csr")),
     ShapeError, r"matrix M must be square"),
    ("M-empty", "matrix", "M of shape (0, 0)", lambda t, d: ms.models.Index3Model(
        np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0)), None, np.zeros((0, 1)), np.zeros((1, 0))),
     ShapeError, r"matrix M is empty"),
    ("D-shape", "matrix", "D not n1 x n1", lambda t, d: _model(D=sp.identity(5)), ShapeError,
     r"matrix D has shape \(5, 5\); expected \(6, 6\)"),
    ("K-shape", "matrix", "K not n1 x n1", lambda t, d: _model(K=sp.identity(7)), ShapeError, r"matrix K has shape"),
    ("G-columns", "matrix", "G with n1 - 1 columns", lambda t, d: _model(G=sp.csr_matrix(np.ones((1, 5)))),
     ShapeError, r"matrix G has 5 columns; expected n1 = 6"),
    ("G-too-many-rows", "matrix", "n2 >= n1", lambda t, d: _model(G=sp.identity(6, format="csr")), ShapeError,
     r"matrix G has n2 = 6 rows; expected n2 < n1"),
    ("F-rows", "matrix", "F with n1 - 1 rows", lambda t, d: _model(F=np.ones((5, 1))), ShapeError,
     r"matrix F has 5 rows; expected n1 = 6"),
    ("L-columns", "matrix", "L with n1 + 1 columns", lambda t, d: _model(L=np.ones((1, 7))), ShapeError,
     r"matrix L has 7 columns; expected n1 = 6"),
    ("F-no-columns", "matrix", "F of shape (n1, 0)", lambda t, d: _model(F=np.zeros((6, 0))), ShapeError,
     r"at least one input and one output"),
    ("K-nan", "matrix", "NaN entry in K", lambda t, d: _model(K=_parts()["K"] * np.nan), InputError,
     r"matrix K has non-finite entries"),
    ("F-inf", "matrix", "inf entry in F", lambda t, d: _model(F=np.full((6, 1), np.inf)), InputError,
     r"matrix F has non-finite entries"),
    ("K-complex", "matrix", "complex K (nonzero imaginary part)", lambda t, d: _model(K=_parts()["K"] * (1 + 1j)),
     InputError, r"matrix K is complex with a nonzero imaginary part"),
    ("F-object", "matrix", "F of dtype object", lambda t, d: _model(F=np.array([[None]] * 6)), InputError,
     r"matrix F has dtype object"),
    ("L-strings", "matrix", "L of strings", lambda t, d: _model(L=np.array([["a"] * 6])), InputError,
     r"matrix L has non-numeric dtype"),
    ("M-ragged", "matrix", "M as a ragged nested list", lambda t, d: _model(M=[[1.0, 2.0], [3.0]]), InputError,
     r"matrix M is not a rectangular array"),
    ("M-3d", "matrix", "M with 3 dimensions", lambda t, d: _model(M=np.ones((6, 6, 1))), ShapeError,
     r"matrix M must be 2-D"),
    ("G-zero-row", "matrix", "a zero row in G", lambda t, d: _model(G=sp.csr_matrix(np.vstack([
        _parts()["G"].toarray(), np.zeros((1, 6))]))), ModelError, r"matrix G has zero rows \[1\]"),
    ("G-rank", "matrix", "G with two equal rows", lambda t, d: _model(G=sp.csr_matrix(np.vstack([
        _parts()["G"].toarray()] * 2))), ModelError, r"matrix G is numerically rank deficient"),
    ("M-singular", "matrix", "singular M with constraints", lambda t, d: _model(M=sp.diags([1.0, 1, 1, 1, 1, 0])),
     ModelError, r"matrix M is singular; the constraint check needs M\^-1"),
    ("band-order", "model", "band = (1, 0.1)", lambda t, d: _model(band=(1.0, 0.1)), InputError,
     r"band must satisfy 0 < lo < hi < inf"),
    ("band-pair", "model", "band = 5", lambda t, d: _model(band=5), InputError, r"band must be a pair"),
    # -- evaluation ---------------------------------------------------------------------
    ("s-nan", "argument", "transfer(nan)", lambda t, d: _small().transfer(np.nan), InputError,
     r"s must be finite"),
    ("s-text", "argument", "transfer('1j')", lambda t, d: _small().transfer("x"), InputError,
     r"s must be a scalar number"),
    ("omega-empty", "argument", "freqresp([])", lambda t, d: _small().freqresp([]), InputError,
     r"omega must be a non-empty 1-D array"),
    ("omega-complex", "argument", "freqresp([1j])", lambda t, d: _small().freqresp([1j]), InputError,
     r"omega must be real"),
    ("omega-nan", "argument", "freqresp([nan])", lambda t, d: _small().freqresp([np.nan]), InputError,
     r"omega has non-finite entries"),
    ("s-pole", "argument", "transfer(s) at a pole", lambda t, d: _pole_model().transfer(1.0), SingularShiftError,
     r"exactly singular: the shift is a pole"),
    ("coeffs-nan", "argument", "SaddlePointSolver.factor(coeffs=(nan, 0, 1))",
     lambda t, d: _small().new_solver().factor(coeffs=(np.nan, 0.0, 1.0)), InputError, r"coeffs must be finite"),
    ("rhs-rows", "argument", "SaddleLU.solve with a wrong number of rows",
     lambda t, d: _small().new_solver().factor(1j).solve(np.ones(3)), InputError, r"rhs has 3 rows"),
    # -- generators and the catalog --------------------------------------------------------------
    ("dsms-g", "generator", "dsms(g=3)", lambda t, d: ms.models.dsms(3), InputError, r"g must be finite and >= 4"),
    ("tcom-odd", "generator", "tcom(nc=5) constrained", lambda t, d: ms.models.tcom(5), InputError,
     r"nc must be even for the constrained TCOM"),
    ("random-n2", "generator", "random_constrained(n1=10, n2=6)",
     lambda t, d: ms.models.random_constrained(n1=10, n2=6), InputError, r"n2 must be an integer in \[0, 5\]"),
    ("random-damping", "generator", "random_constrained(damping='viscous')",
     lambda t, d: ms.models.random_constrained(damping="viscous"), InputError, r"damping must be one of"),
    ("random-spread", "generator", "random_constrained(mass_spread=20)",
     lambda t, d: ms.models.random_constrained(mass_spread=20), InputError, r"mass_spread must be finite and in"),
    ("random-unit", "generator", "random_constrained(stiffness_unit=-1)",
     lambda t, d: ms.models.random_constrained(stiffness_unit=-1.0), InputError,
     r"stiffness_unit must be finite and in \(0"),
    ("fem-size", "generator", "fem_beam(nx=-3)", lambda t, d: ms.models.fem_beam(nx=-3), InputError,
     r"nx must be finite and >= 1"),
    ("fem-point", "generator", "fem_beam(inputs='nose:z')", lambda t, d: ms.models.fem_beam(inputs="nose:z"),
     InputError, r"inputs: unknown point 'nose'"),
    ("catalog-name", "model spec", "'nope:g=3'", lambda t, d: ms.models.parse("nope:g=3"), InputError,
     r"unknown model 'nope'; available: dsms, fem_beam, fem_block, random, tcom"),
    ("catalog-param", "model spec", "'dsms:h=3'", lambda t, d: ms.models.parse("dsms:h=3"), InputError,
     r"model 'dsms' has no parameter 'h'"),
    ("catalog-syntax", "model spec", "'dsms:g'", lambda t, d: ms.models.parse("dsms:g"), InputError,
     r"expected key=value, got 'g'"),
    # -- files ---------------------------------------------------------------------------------------
    ("file-missing", "file", "load('nothing.npz')", lambda t, d: ms.models.load(t / "nothing.npz"),
     FileFormatError, r"does not exist or is not a file"),
    ("file-extension", "file", "load('model.txt')", lambda t, d: ms.models.load(_write(t / "model.txt", "x")),
     FileFormatError, r"unknown extension '\.txt'; expected \.mat, \.npz, \.mtx or a Matrix Market set"),
    ("npz-corrupt", "file", "a .npz that is not a zip", lambda t, d: ms.models.load(_write(t / "bad.npz", "junk")),
     FileFormatError, r"not a readable npz file"),
    ("npz-key", "file", ".npz without F", lambda t, d: ms.models.load(_npz_without(t, "F")), FileFormatError,
     r"missing key F"),
    ("npz-format", "file", ".npz without the format tag", lambda t, d: ms.models.load(_npz_without(t, "format")),
     FileFormatError, r"entry 'format' is missing"),
    ("mat-corrupt", "file", "a .mat that is not MATLAB", lambda t, d: ms.models.load(_write(t / "bad.mat", "junk")),
     FileFormatError, r"not a readable \.mat file"),
    ("mat-G", "file", ".mat without G", lambda t, d: ms.models.load(_mat_without(t, d, "G")), FileFormatError,
     r"missing matrix G"),
    ("mat-sign", "file", "M.E.S.S. file read with sign='physical'",
     lambda t, d: ms.models.load_mat(d / DATA_FILE, sign="physical"), FileFormatError,
     r"does not follow the sign='physical' convention"),
    ("mat-sign-option", "option", "load_mat(sign='negative')",
     lambda t, d: ms.models.load_mat(d / DATA_FILE, sign="negative"), InputError,
     r"sign must be 'mess' or 'physical'"),
    ("mat73-not-matlab", "file", "an HDF5 .mat without MATLAB_class attributes",
     lambda t, d: ms.models.load(_hdf5(t, "plain.mat")), FileFormatError,
     r"an HDF5 file but not a MATLAB v7\.3 file"),
    ("mat73-missing", "file", "v7.3 .mat with M only", lambda t, d: ms.models.load(_hdf5(t, "m.mat", "double")),
     FileFormatError, r"missing matrix D, K, G \(found \['M'\]\)"),
    ("mat73-class", "file", "v7.3 .mat whose M is a struct",
     lambda t, d: ms.models.load(_hdf5(t, "s.mat", "struct", keys=("M", "D", "K", "G"))), FileFormatError,
     r"variable 'M' has MATLAB class 'struct'; expected a numeric matrix"),
    ("mat73-truncated", "file", "a v7.3 header without HDF5 data",
     lambda t, d: ms.models.load(_write(t / "h.mat", "MATLAB 7.3 MAT-file".ljust(124) + "\0\x02IM" + "\0" * 400)),
     FileFormatError, r"says MATLAB v7\.3 \(HDF5\) but holds no HDF5 data"),
    ("mtx-no-set", "file", "load('none') with no such file or set", lambda t, d: ms.models.load(t / "none"),
     FileFormatError, r"does not exist, and no Matrix Market set has that stem"),
    ("mtx-no-damping", "file", "Matrix Market set without D", lambda t, d: ms.models.load(_mtx_set(t, "s", ["D"])),
     FileFormatError, r"no file for matrix D \(looked for key D; found m_B\.mtx.*names=\{'D': None\}"),
    ("mtx-two-sets", "file", "directory holding two Matrix Market sets",
     lambda t, d: ms.models.load((_mtx_set(t, "two"), _write(t / "two" / "n_M.mtx", "x"),
                                  _write(t / "two" / "n_K.mtx", "x"))[0]),
     FileFormatError, r"holds several Matrix Market sets \(stems 'm', 'n'\)"),
    ("mtx-both-F-B", "file", "a set with both F.mtx and B.mtx",
     lambda t, d: ms.models.load(_mtx_set(t, "fb", F=_small().F)), FileFormatError,
     r"both m_F\.mtx and m_B\.mtx could be matrix F"),
    ("mtx-unreadable", "file", "a .mtx that is not Matrix Market",
     lambda t, d: ms.models.load((_mtx_set(t, "u"), _write(t / "u" / "m_K.mtx", "junk"))[0]), FileFormatError,
     r"m_K\.mtx: not a readable Matrix Market file"),
    ("mtx-sign", "file", "set with M.E.S.S. signs read as physical",
     lambda t, d: ms.models.load(_mtx_set(t, "ms", sign="mess")), FileFormatError,
     r"no positive diagonal entry .*\(try sign='mess'"),
    ("mtx-velocity-output", "file", "first-order C with a velocity output",
     lambda t, d: ms.models.load(_mtx_set(t, "v", C=np.ones((1, 41)))), FileFormatError,
     r"C has nonzeros outside its first n1 = 20 columns \(velocity outputs\)"),
    ("mtx-names", "option", "load_mtx(names={'Q': 'E'})",
     lambda t, d: ms.models.load_mtx(_mtx_set(t, "n"), names={"Q": "E"}), InputError,
     r"names: unknown matrix 'Q'; valid: M, D, K, G, F, L"),
    ("save-non-model", "argument", "save_npz(a dict)", lambda t, d: ms.models.save_npz({}, t / "x.npz"),
     InputError, r"model must be an Index3Model; got dict"),
    ("rom-missing", "file", "load_rom('none.npz')", lambda t, d: ms.rom.load_rom(t / "none.npz"),
     FileFormatError, r"ROM file .* does not exist"),
    ("rom-kind", "file", "ROM .npz without 'kind'",
     lambda t, d: ms.rom.load_rom((np.savez(t / "r.npz", M=np.eye(1)), t / "r.npz")[1]),
     FileFormatError, r"entry 'kind' missing or unknown"),
    ("rom-changed", "file", "load_rom of a .npz changed after save_rom", lambda t, d: _changed_rom_file(t),
     FileFormatError, r"c\.npz'?: SHA-256 .* differs from .* recorded in .*c\.json"),
    ("rom-formats", "argument", "save_rom(formats=('npz', 'hdf5'))",
     lambda t, d: ms.romfiles.save_rom(_rom(), t / "r", formats=("npz", "hdf5")), InputError,
     r"formats must be distinct names out of npz, mat; got \['npz', 'hdf5'\]"),
    ("rom-extension", "argument", "rom.save('rom.txt')",
     lambda t, d: ms.rom.SecondOrderROM(np.eye(1), np.eye(1), np.eye(1), np.ones(1), np.ones(1)).save(t / "r.txt"),
     InputError, r"extension must be \.npz or \.mat"),
    # -- reducers: names, options, r ----------------------------------------------------------------
    ("reducer-name", "option", "make('irk', fom)", lambda t, d: ms.reducers.make("irk", _small()), OptionError,
     r"unknown reducer 'irk'; available: .*irka"),
    ("reducer-fom", "argument", "make('irka', a matrix)", lambda t, d: ms.reducers.make("irka", np.eye(3)),
     InputError, r"fom must be an Index3Model"),
    ("option-unknown", "option", "irka(tolerance=1e-6)", lambda t, d: _irka(tolerance=1e-6), OptionError,
     r"IRKA got unknown option\(s\) 'tolerance'; valid options: .*tol"),
    ("option-tol", "option", "irka(tol=-1)", lambda t, d: _irka(tol=-1), OptionError,
     r"The 'tol' parameter of IRKA must be a float in \(0, 1\)\. Got -1 instead\."),
    ("option-maxit", "option", "irka(maxit=0)", lambda t, d: _irka(maxit=0), OptionError,
     r"The 'maxit' parameter of IRKA must be an int in \[1, inf\)"),
    ("option-bool", "option", "irka(maxit=True)", lambda t, d: _irka(maxit=True), OptionError,
     r"The 'maxit' parameter of IRKA must be an int"),
    ("option-choice", "option", "irka(update='newton')", lambda t, d: _irka(update="newton"), OptionError,
     r"The 'update' parameter of IRKA must be one of 'auto', 'bt', 'residue'"),
    ("option-nan-shift", "option", "irka(init='given', init_shifts=[nan])",
     lambda t, d: _irka(init="given", init_shifts=[np.nan]), OptionError,
     r"The 'init_shifts' parameter of IRKA must be an array of numbers"),
    ("given-missing", "option", "irka(init='given') without init_shifts", lambda t, d: _irka(init="given"),
     InputError, r"init='given' needs the option init_shifts"),
    ("given-unused", "option", "irka(init_shifts=[1.0]) with init='logspace'", lambda t, d: _irka(init_shifts=[1.0]),
     InputError, r"only used with init='given'"),
    ("given-lhp", "option", "init_shifts in the left half-plane",
     lambda t, d: _irka(init="given", init_shifts=[-1.0, 0.5]).reduce(2), InputError,
     r"init_shifts must lie in the open right half-plane"),
    ("given-imag-axis", "option", "init_shifts on the imaginary axis",
     lambda t, d: _irka(init="given", init_shifts=[1j, -1j]).reduce(2), InputError,
     r"init_shifts must lie in the open right half-plane"),
    ("given-conjugate", "option", "init_shifts not closed under conjugation",
     lambda t, d: _irka(init="given", init_shifts=[1 + 1j, 2.0]).reduce(2), InputError,
     r"init_shifts must be closed under complex conjugation"),
    ("r-zero", "argument", "reduce(0)", lambda t, d: _irka().reduce(0), InputError,
     r"r must be a positive integer; got 0"),
    ("r-float", "argument", "reduce(2.5)", lambda t, d: _irka().reduce(2.5), InputError,
     r"r must be a positive integer; got 2\.5"),
    ("r-bool", "argument", "reduce(True)", lambda t, d: _irka().reduce(True), InputError,
     r"r must be a positive integer; got True"),
    ("r-order", "argument", "reduce(r) with r > n1 - n2", lambda t, d: _irka().reduce(20), InputError,
     r"r = 20 exceeds the order of the full model on its hidden manifold \(n1 - n2 = 19\)"),
    ("krylov-points-empty", "option", "krylov(points=[])",
     lambda t, d: ms.reducers.make("krylov", _small(), points=[]), OptionError, r"'points' parameter .* non-empty"),
    ("krylov-points-nan", "option", "krylov(points=[nan])",
     lambda t, d: ms.reducers.make("krylov", _small(), points=[np.nan]), OptionError, r"'points' parameter .* finite"),
    ("krylov-points-left", "option", "krylov(points=[-1.0])",
     lambda t, d: ms.reducers.make("krylov", _small(), points=[-1.0]), OptionError,
     r"'points' parameter .* right half-plane"),
    ("krylov-points-pole", "argument", "krylov(points=[1.0]) at a pole of the model",
     lambda t, d: ms.reducers.make("krylov", _pole_model(), points=[1.0]).reduce(2), SingularShiftError,
     r"'points' parameter of Krylov: points\[0\] = 1.0 is \(numerically\) a pole"),
    ("krylov-r-order", "argument", "krylov reduce(r) with r > n1 - n2",
     lambda t, d: ms.reducers.make("krylov", _small()).reduce(20), InputError, r"r = 20 exceeds the order"),
    ("projected-memory", "option", "irka-projected over its memory budget",
     lambda t, d: ms.reducers.make("irka-projected", ms.models.dsms(2000), memory_budget_gib=0.01), MemoryBudgetError,
     r"would need about .* GiB .* above the budget memory_budget_gib = 0\.01"),
    ("modal-selection", "option", "modal(selection='highest')", lambda t, d: _modal(selection="highest"),
     OptionError, r"The 'selection' parameter of Modal must be one of 'lowest', 'band', 'dominance'"),
    ("modal-band", "option", "modal(band=[2, 1]) (an empty band)", lambda t, d: _modal(band=[2.0, 1.0]),
     InputError, r"The 'band' parameter of Modal must be \(w1, w2\) with 0 <= w1 < w2.*empty"),
    ("modal-r-order", "argument", "modal reduce(r) with r > n1 - n2 - 1", lambda t, d: _modal().reduce(19),
     InputError, r"r = 19 exceeds .* \(n1 - n2 - 1 = 18\) for modal"),
    ("modal-r-static", "argument", "modal reduce(r) with r < m static columns",
     lambda t, d: _modal(ms.models.random_constrained(n1=12, n2=2, m=3, p=2, seed=0)).reduce(2), InputError,
     r"r = 2 is smaller than the m = 3 static-correction columns of modal"),
    ("btfl-band", "option", "bt-fl(band=[2, 1]) (an empty band)",
     lambda t, d: ms.reducers.make("bt-fl", _small(), band=[2.0, 1.0]), InputError,
     r"The 'band' parameter of BTFL must satisfy 0 <= w1 < w2 .*the band is empty"),
    ("btfl-limited", "option", "bt-fl(limited='observability')",
     lambda t, d: ms.reducers.make("bt-fl", _small(), limited="observability"), OptionError,
     r"The 'limited' parameter of BTFL must be one of 'controllability', 'both'"),
    ("btfl-nodes", "option", "bt-fl(nodes=0)", lambda t, d: ms.reducers.make("bt-fl", _small(), nodes=0),
     OptionError, r"The 'nodes' parameter of BTFL must be an int in \[1, inf\)"),
    ("btfl-log-zero", "option", "bt-fl(band=[0, 1], variable='log')",
     lambda t, d: ms.reducers.make("bt-fl", _small(), band=[0.0, 1.0], variable="log"), InputError,
     r"variable='log' needs band w1 > 0"),
    ("btfl-r-order", "argument", "bt-fl reduce(r) with r > 2 (n1 - n2) (first order)",
     lambda t, d: ms.reducers.make("bt-fl", _small()).reduce(39), InputError, r"r = 39 exceeds .* for bt-fl"),
    ("free-coupled-damping", "model", "a reducer on a free-floating model whose damping couples rigid and "
     "flexible modes", lambda t, d: ms.reducers.make("bt", ms.models.dsms(20, kappa=0, kappa_end=0)), ModelError,
     r"the damping D of model .* couples its 1 rigid-body modes to the flexible ones"),
    ("free-h2-norm", "argument", "h2_norm of a free-floating model (a pole at s = 0)",
     lambda t, d: ms.analysis.h2_norm(ms.models.dsms(20, free=True)), InputError,
     r"has 1 rigid-body modes, a pole of T at s = 0: its norm is infinite"),
    ("modes-band", "argument", "constrained_modes(band=(1, 1)) (an empty band)",
     lambda t, d: constrained_modes(_small(), band=(1.0, 1.0)), InputError,
     r"band must satisfy 0 <= w1 < w2 .*the band is empty"),
    ("modes-k", "argument", "constrained_modes(k > n1 - n2 - 1)", lambda t, d: constrained_modes(_small(), k=19),
     InputError, r"k = 19 exceeds n1 - n2 - 1 = 18"),
    # -- reduced models and analysis -----------------------------------------------------------------
    ("rom-nan", "matrix", "SecondOrderROM with a NaN in K",
     lambda t, d: ms.rom.SecondOrderROM(np.eye(2), np.eye(2), np.full((2, 2), np.nan), np.ones(2), np.ones(2)),
     InputError, r"matrix K has non-finite entries"),
    ("rom-shape", "matrix", "SecondOrderROM with a non-square M",
     lambda t, d: ms.rom.SecondOrderROM(np.ones((2, 3)), np.eye(2), np.eye(2), np.ones(2), np.ones(2)),
     ShapeError, r"matrix M must be square"),
    ("grid-band", "argument", "freq_grid((1, 0.1))", lambda t, d: ms.analysis.freq_grid((1.0, 0.1)), InputError,
     r"band must satisfy 0 < lo < hi"),
    ("sigma-shape", "argument", "sigma_max of a 4-D array", lambda t, d: ms.analysis.sigma_max(np.ones((2, 2, 2, 2))),
     InputError, r"H must have shape \(k, p, m\) or \(p, m\)"),
    ("errors-H", "argument", "errors(..., H_full of the wrong length)",
     lambda t, d: ms.analysis.errors(_small(), _irka(maxit=2).reduce(2).rom, [0.1, 0.2], H_full=np.ones((3, 3, 1))),
     InputError, r"H_full has 3 frequencies; omega has 2"),
    # -- exact error norms (inf with a StabilityWarning for an unstable ROM: tests/test_studies_norms_time.py) --
    ("h2-io", "norms", "h2_error of a ROM with other input/output dimensions",
     lambda t, d: ms.analysis.h2_error(_small(), _other_io_rom()), ShapeError, r"rom has 2 inputs and 2 outputs"),
    ("hinf-io", "norms", "hinf_error of a ROM with other input/output dimensions",
     lambda t, d: ms.analysis.hinf_error(_small(), _other_io_rom()), ShapeError, r"rom has 2 inputs and 2 outputs"),
    ("h2-nan", "norms", "h2_error of a ROM whose K became NaN", lambda t, d: ms.analysis.h2_error(_small(), _nan_rom()),
     InputError, r"matrix K has non-finite entries"),
    ("hinf-nan", "norms", "hinf_error of a ROM whose K became NaN",
     lambda t, d: ms.analysis.hinf_error(_small(), _nan_rom()), InputError, r"matrix K has non-finite entries"),
    ("norm-kind", "norms", "error_norms(kinds=['h3'])",
     lambda t, d: ms.analysis.error_norms(_small(), _rom(), kinds=["h3"]), OptionError, r"norm must be one of"),
    # -- time-domain simulation (an unstable ROM is simulated and flagged: tests/test_simulate.py) ---------------
    ("sim-step", "time", "time_grid(horizon=1, step=2)", lambda t, d: ms.analysis.signals.time_grid(1.0, 2.0),
     InputError, r"step 2.0 is larger than the horizon 1.0"),
    ("sim-nan-u", "time", "simulate with a NaN input sample", lambda t, d: _sim(u_edit=True), InputError,
     r"u has non-finite samples \(NaN or inf\), first at t\[3\]"),
    ("sim-channels", "time", "simulate with 2 input channels for m = 1", lambda t, d: _sim(m=2), InputError,
     r"u has 2 channels \(columns\); the model has m = 1"),
    ("sim-csv-channels", "time", "input CSV with 2 channels for m = 1",
     lambda t, d: ms.analysis.signals.read_csv(_write(t / "u.csv", "t,u1,u2\n0,1,1\n1,1,1\n"), m=1), InputError,
     r"has 2 input columns; the model has m = 1"),
    ("sim-steps", "time", "more than 10,000,000 steps",
     lambda t, d: ms.analysis.compare.time_input((1e-2, 1.0), 1, horizon=1e6, step=1e-3), InputError,
     r"at most 10,000,000 are simulated"),
    ("spec-time-step", "study spec", "time scene with step > horizon", lambda t, d: _time_spec(horizon=1.0, step=2.0),
     SpecError, r"scenes\[0\] \('s'\): time-domain input on model 'd'.*larger than the horizon"),
    ("spec-time-direction", "study spec", "time scene direction of length 2 for m = 1",
     lambda t, d: _time_spec(direction=[1.0, 1.0]), SpecError, r"direction must have m = 1 entries"),
    ("spec-time-input", "study spec", "time scene input 'ramp'", lambda t, d: _time_spec(input="ramp"), SpecError,
     r"unknown value 'ramp'.*valid choices: step, impulse, chirp, multisine, csv"),
    ("spec-norms", "study spec", "norms = ['h3']", lambda t, d: _spec(norms=["h3"]), SpecError,
     r"norms: unknown value 'h3'.*valid choices: h2, hinf"),
    ("spec-norm-grid", "study spec", "measure 'h2' with a grid",
     lambda t, d: _spec(scenes=[{"name": "s", "kind": "error_vs_r", "model": "d", "r": 2, "measure": "h2",
                                 "grid": "default"}]), SpecError, r"measure 'h2' is a norm over the whole"),
    ("spec-norm-option", "study spec", "norm_options h2 rtol = 2", lambda t, d: _spec(norm_options={"h2": {"rtol": 2}}),
     SpecError, r"norm_options.h2.rtol: expected a number in \(0, 1\)"),
    # -- low-rank ADI ------------------------------------------------------------------------------
    ("adi-tol", "option", "lradi(tol=2)", lambda t, d: _lradi()(_small(), tol=2.0), InputError,
     r"tol must be a float in \(0, 1\)"),
    ("adi-shifts", "option", "lradi(shifts=[1.0]) (right half-plane)", lambda t, d: _lradi()(_small(), shifts=[1.0]),
     InputError, r"shifts must lie in the open left half-plane"),
    ("adi-equation", "option", "lradi(equation='both')", lambda t, d: _lradi()(_small(), equation="both"),
     InputError, r"equation must be 'controllability' or 'observability'"),
    # -- study specifications ---------------------------------------------------------------------------
    ("spec-missing", "study spec", "load_spec('none.toml')",
     lambda t, d: __import__("morsuite.studies.spec", fromlist=["load_spec"]).load_spec(t / "none.toml"),
     SpecError, r"study spec .*none\.toml' does not exist"),
    ("spec-toml", "study spec", "a file that is not TOML",
     lambda t, d: __import__("morsuite.studies.spec", fromlist=["load_spec"]).load_spec(_write(t / "s.toml", "[[x")),
     SpecError, r"not valid TOML"),
    ("spec-key", "study spec", "scene key 'gird'", lambda t, d: _spec(scene_gird="default"), SpecError,
     r"unknown key 'gird'.*did you mean 'grid'"),
    ("spec-kind", "study spec", "scene kind 'errors'", lambda t, d: _spec(scene_kind="errors"), SpecError,
     r"unknown value 'errors'.*valid choices"),
    ("spec-model", "study spec", "model 'nope:g=3'", lambda t, d: _spec(models={"d": "nope:g=3"}), SpecError,
     r"unknown model 'nope'"),
    ("spec-reducer", "study spec", "method with reducer 'irk'",
     lambda t, d: _spec(methods={"irka": {"reducer": "irk"}}), SpecError, r"unknown reducer 'irk'"),
    ("spec-option", "study spec", "method option tol = 2",
     lambda t, d: _spec(methods={"irka": {"options": {"tol": 2}}}), SpecError,
     r"The 'tol' parameter of IRKA must be a float in \(0, 1\)"),
    ("spec-r", "study spec", "r above n1 - n2", lambda t, d: _spec(scene_r=40), SpecError,
     r"r = 40 exceeds the order n1 - n2 = 19"),
    ("spec-r-type", "study spec", "r = 'ten'", lambda t, d: _spec(scene_r="ten"), SpecError,
     r"expected a positive integer, a list of them"),
    ("spec-name", "study spec", "name with a slash", lambda t, d: _spec(name="a/b"), SpecError,
     r"'a/b' is not a file-name-safe string"),
]


def _registry_rows() -> list:
    """Two rows per reducer of the package, read from the registry (a reducer added later is covered with
    nothing edited here): an unknown option, refused with the list of valid ones, and ``reduce(r)`` one
    above the reducer's largest order. Cost: constructing each reducer on dsms(20) (no LU)."""
    rows = []
    for name in ms.reducers.available():
        cls = ms.reducers.get_class(name)
        if not cls.__module__.startswith("morsuite."):
            continue  # plugins are not this table's
        rows.append((f"registry-{name}-option", "option", f"{name}(nope=1): an unknown option",
                     lambda t, d, n=name: ms.reducers.make(n, _small(), nope=1), OptionError,
                     rf"{cls.__name__} got unknown option\(s\) 'nope'; valid options: "))
        rows.append((f"registry-{name}-order", "argument", f"{name} reduce(r) one above its largest order",
                     lambda t, d, n=name: _above_order(ms.reducers.make(n, _small())), InputError,
                     r"r = \d+ exceeds"))
    return rows


def _above_order(red):
    return red.reduce(red.max_order() + 1)


_NEEDS_DATA = frozenset({"mat-G", "mat-sign", "mat-sign-option"})
CASES = [Refusal(*row, needs_data=row[0] in _NEEDS_DATA) for row in _ROWS + _registry_rows()]


def table_rows(data_dir=None):
    """Run every row; ``(rows, skipped)``.

    ``rows`` are ``(area, what, got, message, key)`` with the class actually
    raised (``"X (expected Y)"`` on a mismatch, ``"(not refused!)"`` if nothing
    was raised) and the message with the scratch directory shown as ``<dir>``,
    the checkout's data directory as ``tests/data`` (another one as
    ``<data>``), whitespace collapsed and cut at :data:`MAX_MESSAGE`
    characters. ``skipped`` are the keys of the rows that need
    :data:`DATA_FILE` when ``data_dir`` (default :func:`default_data_dir`)
    does not hold it.
    """
    data = Path(data_dir) if data_dir is not None else default_data_dir()
    have_data = data is not None and (data / DATA_FILE).is_file()
    label = "tests/data" if have_data and data.resolve() == _CHECKOUT_DATA else "<data>"
    out, skipped = [], []
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        for case in CASES:
            if case.needs_data and not have_data:
                skipped.append(case.key)
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    case.call(tmp, data)
                except Exception as e:  # noqa: BLE001 - we want its class and message
                    got, msg = type(e).__name__, str(e)
                else:
                    got, msg = "(not refused!)", ""
            msg = msg.replace(str(tmp), "<dir>")
            if have_data:
                msg = msg.replace(str(data), label)
            msg = " ".join(msg.split())
            if len(msg) > MAX_MESSAGE:
                msg = msg[: MAX_MESSAGE - 3] + "..."
            if got != case.error.__name__:
                got = f"{got} (expected {case.error.__name__})"
            out.append((case.area, case.what, got, msg, case.key))
    return out, skipped


def markdown_table(data_dir=None) -> str:
    """The Markdown table of :func:`table_rows`; the keys of the rows left out are printed to stderr."""
    rows, skipped = table_rows(data_dir)
    if skipped:
        print(f"left out (no {DATA_FILE} in the data directory): {', '.join(skipped)}", file=sys.stderr)
    lines = ["| area | input | error | message | test id |", "|---|---|---|---|---|"]
    for area, what, got, msg, key in rows:
        esc = msg.replace("|", "\\|")
        lines.append(f"| {area} | {what.replace('|', '/')} | `{got}` | {esc} | `{key}` |")
    return "\n".join(lines)
