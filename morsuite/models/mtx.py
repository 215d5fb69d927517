"""Matrix Market sets: one file per matrix, as the public benchmark collections ship them.

The Oberwolfach / MOR Wiki second-order benchmarks come as ``NAME.M``,
``NAME.K``, ``NAME.B``, ``NAME.C`` (the butterfly gyroscope's ``gyro.M``, ...);
other collections write ``NAME_M.mtx``; a hand-made export is often a directory
of ``M.mtx``, ``K.mtx``, ... The naming rules are those of
:mod:`morsuite.modelfiles`; the matrices are read with :func:`scipy.io.mmread`
(coordinate files give sparse matrices, array files dense ones).
"""

from __future__ import annotations

import numpy as np
import scipy.io as sio
import scipy.sparse as sp

from ..errors import FileFormatError, InputError
from ..modelfiles import matrix_market_set, set_neighbours
from .index3 import Index3Model
from .layout import check_sign_option, check_stiffness_sign, input_matrix, output_matrix, to_physical

__all__ = ["load_mtx", "ROLES"]

#: the model's matrices and the keys each is looked for under, in order of preference
ROLES = {"M": ("M",), "D": ("D",), "K": ("K",), "G": ("G",), "F": ("F", "B"), "L": ("L", "C")}
#: matrices that may be declared absent with ``names={role: None}``
OPTIONAL = {"D": "zero damping", "G": "no constraints"}


def _keys(names):
    """{role: candidate keys} after the user's ``names``; None marks a declared-absent matrix."""
    if names is None:
        names = {}
    if not isinstance(names, dict):
        raise InputError(f"names must be a dict {{role: key}}; got {type(names).__name__}")
    bad = [r for r in names if r not in ROLES]
    if bad:
        raise InputError(f"names: unknown matrix {', '.join(map(repr, bad))}; valid: {', '.join(ROLES)}")
    out = {}
    for role, cands in ROLES.items():
        if role not in names:
            out[role] = cands
            continue
        key = names[role]
        if key is None:
            if role not in OPTIONAL:
                raise InputError(f"names: matrix {role} cannot be absent (only D and G can: "
                                 f"{', '.join(f'{r}: {w}' for r, w in OPTIONAL.items())})")
            out[role] = None
        elif isinstance(key, str) and key and key.isidentifier():
            out[role] = (key,)
        else:
            raise InputError(f"names[{role!r}] must be a file key such as 'E' (letters, digits, _), or None; "
                             f"got {key!r}")
    return out


def _read(path):
    try:
        X = sio.mmread(str(path))
    except Exception as exc:  # scipy raises ValueError, OSError and others on bad files
        raise FileFormatError(f"{path}: not a readable Matrix Market file ({type(exc).__name__}: {exc})") from exc
    return sp.csr_matrix(X) if sp.issparse(X) else np.asarray(X)


def load_mtx(path, *, names=None, sign: str = "physical", name: str | None = None, band=(1e-2, 1.0),
             check_sign: bool = True, check_constraints: bool = True) -> Index3Model:
    """Load a second-order index-3 model from a set of Matrix Market files.

    Parameters
    ----------
    path : path-like
        The set: its directory (holding one set), its stem (``data/gyro`` for
        ``data/gyro.M``, ``data/gyro.K``, ...) or one of its files. Names
        accepted: ``STEM.KEY``, ``STEM_KEY.mtx``, ``STEM.KEY.mtx``,
        ``STEM-KEY.mtx``, ``KEY.mtx`` (also ``.mtx.gz``, ``.mtx.bz2``); see
        :mod:`morsuite.modelfiles`.
    names : dict, optional
        The key each matrix is stored under, where it is not the default:
        M, D, K, G under their own letters, F under ``F`` or ``B``, L under
        ``L`` or ``C``. ``{"D": "E"}`` takes the damping from ``NAME.E``;
        ``{"D": None}`` declares an undamped model, ``{"G": None}`` one
        without constraints. A missing D or G is otherwise an error: an
        absent file must not silently become a zero matrix.
    sign : {"physical", "mess"}
        ``"physical"`` (default): D and K as stored. ``"mess"``: stored
        negated (the M.E.S.S. convention of :func:`~morsuite.models.load_mat`).
    name : str, optional
        Model name (default: the stem, or the directory's name).
    band : (float, float)
        Default frequency band in rad/s (default (1e-2, 1)).
    check_sign : bool
        Refuse a stiffness whose diagonal, in the physical convention, is
        nowhere positive and somewhere negative (default True).
    check_constraints : bool
        Check that G has full row rank (default True; see
        :class:`~morsuite.models.Index3Model`).

    B and C may be the second-order F (n1 x m) and L (p x n1) or the
    first-order ``[0; F; 0]`` and ``[L, 0, 0]`` (:mod:`.layout`).

    Cost: parsing the text files (about 1 s per million nonzeros); one sparse
    LU of M for the constraint check.

    Raises
    ------
    FileFormatError
        No set at ``path``, several sets in a directory, a required matrix
        missing (named, with the files found), two files for one matrix, an
        unreadable file, or a B or C that is not the second-order layout.
    InputError
        A bad ``names`` or ``sign`` option; inconsistent shapes or contents
        are refused by :class:`~morsuite.models.Index3Model`.
    """
    check_sign_option(sign)
    roles = _keys(names)
    keys = sorted({k.upper() for c in roles.values() if c for k in c})
    directory, stem, members = matrix_market_set(path, keys)
    where = f"Matrix Market set {str(directory / stem) if stem else str(directory)!r}"
    listing = ", ".join(set_neighbours(directory, stem))
    chosen, stored = {}, {}
    for role, cands in roles.items():
        if cands is None:
            continue
        present = [k for k in cands if k.upper() in members]
        if len(present) > 1:
            raise FileFormatError(f"{where}: both {' and '.join(members[k.upper()].name for k in present)} "
                                  f"could be matrix {role}; say which with names={{{role!r}: {present[0]!r}}}")
        if not present:
            hint = (f"; names={{{role!r}: 'KEY'}} if it is stored under another key"
                    + (f", names={{{role!r}: None}} for {OPTIONAL[role]}" if role in OPTIONAL else ""))
            raise FileFormatError(f"{where}: no file for matrix {role} (looked for key "
                                  f"{' or '.join(cands)}; found {listing}){hint}")
        chosen[role] = members[present[0].upper()]
        stored[role] = present[0]
    # one file cannot play two roles (names={"D": "C"} with C also taken as L)
    used = {}
    for role, f in chosen.items():
        if f in used:
            raise FileFormatError(f"{where}: {f.name} would be both matrix {used[f]} and {role}; "
                                  "name the other one with names=")
        used[f] = role
    mats = {role: _read(f) for role, f in chosen.items()}
    M = mats["M"]
    n1 = M.shape[0]
    D = mats.get("D", sp.csr_matrix((n1, n1)))
    G = mats.get("G")
    F = input_matrix(mats["F"], n1, chosen["F"], stored["F"])
    L = output_matrix(mats["L"], n1, chosen["L"], stored["L"])
    D, K = to_physical(D, mats["K"], sign)
    if check_sign:
        check_stiffness_sign(K, sign, where)
    return Index3Model(M, D, K, G, F, L, name=name or stem or directory.name, band=band,
                       check_constraints=check_constraints)
