"""Which files a model path names: single files and Matrix Market sets.

A model on disk is one file (``.mat``, M.E.S.S. layout, MATLAB v5/v7 or v7.3;
``.npz``, morsuite's own) or a *Matrix Market set*: one file per matrix, as the
public benchmark collections ship them. The member names accepted are

=========================  ==========================================================
``STEM.KEY``               the Oberwolfach / MOR Wiki style: ``gyro.M``, ``gyro.K``,
                           ``rail_1357_c60.B`` (Matrix Market content, no extension)
``STEM_KEY.mtx``           ``beam_M.mtx``, ``beam_K.mtx``
``STEM.KEY.mtx``           ``beam.M.mtx``
``STEM-KEY.mtx``           ``beam-M.mtx``
``KEY.mtx``                a directory holding one model: ``model/M.mtx``, ``model/K.mtx``
=========================  ==========================================================

each also with ``.mtx.gz`` / ``.mtx.bz2`` instead of ``.mtx``. With a ``.mtx``
ending KEY is matched without regard to case (``beam_m.mtx`` is ``M``);
``STEM.KEY`` needs KEY's own case (``gyro.m`` is a MATLAB script, not ``M``).
A set is named by its directory (``model/``, when it holds one set), by its stem
(``data/gyro``: the files ``data/gyro.M``, ``data/gyro.K``, ...) or by any one
of its files.

This module imports nothing numerical: a study whose models are all cached
decides which files a model spec names, and hashes them, without importing
:mod:`morsuite.models` (see :mod:`morsuite.studies.memo`).
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import FileFormatError

__all__ = ["MODEL_FILE_ENDINGS", "MTX_ENDINGS", "DEFAULT_KEYS", "is_model_path", "split_member",
           "matrix_market_set", "set_neighbours", "model_files"]

#: name endings of the Matrix Market files (compressed ones are read as they are)
MTX_ENDINGS = (".mtx", ".mtx.gz", ".mtx.bz2")
#: name endings of the model files morsuite.models.load recognises by their name
MODEL_FILE_ENDINGS = (".mat", ".npz") + MTX_ENDINGS
#: separators between stem and key
SEPARATORS = "._-"
#: the matrix names (keys) a set is searched for by default: the morsuite names and the
#: first-order names B, C that the collections use for the input and output matrices
DEFAULT_KEYS = ("M", "D", "K", "G", "F", "L", "B", "C")


def is_model_path(spec) -> bool:
    """True if the model spec ``spec`` names files rather than a catalog model.

    A path ends with one of :data:`MODEL_FILE_ENDINGS`, contains a path
    separator, or starts with ``.`` or ``~``; catalog specs (``dsms:g=600``)
    have none of these. A Matrix Market set in the working directory is
    written ``./gyro``.
    """
    if not isinstance(spec, str) or not spec:
        return False
    return (spec.lower().endswith(MODEL_FILE_ENDINGS) or "/" in spec or os.sep in spec
            or spec.startswith((".", "~")))


def split_member(filename: str, keys=DEFAULT_KEYS):
    """``(stem, KEY)`` if ``filename`` is a member of a Matrix Market set, else None.

    ``KEY`` is returned upper-case as listed in ``keys``; the stem is ``""``
    for ``KEY.mtx``.
    """
    low = filename.lower()
    ending = next((e for e in MTX_ENDINGS if low.endswith(e)), "")
    base = filename[: len(filename) - len(ending)]
    for key in sorted(keys, key=len, reverse=True):
        k = len(key)
        if base.lower() == key.lower():
            if ending:
                return "", key.upper()
            continue
        if len(base) > k + 1 and base[-k:].lower() == key.lower() and base[-k - 1] in SEPARATORS:
            # without the .mtx ending only STEM.KEY with the key's own case counts: a
            # MATLAB script gyro.m is not the mass matrix of the set gyro
            if ending or (base[-k - 1] == "." and base[-k:] == key):
                return base[: -k - 1], key.upper()
    return None


def _members(directory: Path, keys):
    """{stem: {KEY: path}} of the set members in ``directory``; duplicate keys are refused."""
    sets = {}
    for f in sorted(directory.iterdir()):
        if not f.is_file() or f.name.startswith("."):
            continue
        hit = split_member(f.name, keys)
        if hit is None:
            continue
        stem, key = hit
        other = sets.setdefault(stem, {}).get(key)
        if other is not None:
            raise FileFormatError(f"{directory}: both {other.name!r} and {f.name!r} would be matrix {key} "
                                  f"of the Matrix Market set {stem or '(no stem)'!r}; remove or rename one")
        sets[stem][key] = f
    return sets


def matrix_market_set(path, keys=DEFAULT_KEYS):
    """The Matrix Market set that ``path`` names: ``(directory, stem, {KEY: path})``.

    ``path`` is a directory holding one set, a stem (``data/gyro``) or one
    member file (``data/gyro.M``). Only members whose key is in ``keys`` are
    listed. Raises :class:`~morsuite.errors.FileFormatError` when no set is
    found, a directory holds several, or two files claim the same key.
    """
    p = Path(path).expanduser()
    forms = "STEM.KEY, STEM_KEY.mtx, STEM.KEY.mtx, STEM-KEY.mtx or KEY.mtx"
    if p.is_dir():
        # a model has at least M, K, F and L: a lone stray name such as notes.d is no set
        sets = {s: m for s, m in _members(p, keys).items() if len(m) > 1}
        if not sets:
            raise FileFormatError(f"directory {str(p)!r} holds no Matrix Market set (files named {forms}, "
                                  f"KEY one of {', '.join(keys)})")
        if len(sets) > 1:
            stems = ", ".join(repr(s or "(no stem)") for s in sets)
            raise FileFormatError(f"directory {str(p)!r} holds several Matrix Market sets (stems {stems}); "
                                  f"name one by its stem, e.g. {str(p / (next(iter(sets)) or 'M.mtx'))!r}")
        stem, members = next(iter(sets.items()))
        return p, stem, members
    if p.is_file():
        hit = split_member(p.name, keys)
        if hit is None:
            raise FileFormatError(f"{str(p)!r} is not named as a member of a Matrix Market set ({forms}, "
                                  f"KEY one of {', '.join(keys)})")
        directory, stem = p.parent, hit[0]
    else:
        directory, stem = p.parent, p.name
        if not directory.is_dir():
            raise FileFormatError(f"model file {str(p)!r} does not exist (nor does its directory)")
    members = _members(directory, keys).get(stem, {})
    if not members:
        raise FileFormatError(f"model file {str(p)!r} does not exist, and no Matrix Market set has that stem "
                              f"(looked for {forms} in {str(directory)!r})")
    return directory, stem, members


def set_neighbours(directory, stem) -> list[str]:
    """Names of the files that look like members of the set ``stem`` under any key (for messages)."""
    directory = Path(directory)
    if stem:
        return sorted(f.name for f in directory.iterdir()
                      if f.is_file() and f.name[:len(stem) + 1] in {stem + c for c in SEPARATORS})
    return sorted(f.name for f in directory.iterdir() if f.is_file() and f.name.lower().endswith(MTX_ENDINGS))


def model_files(path) -> list[Path]:
    """The files a model path names, sorted: the file itself, or every member of its set.

    What a study hashes to know whether a model changed.
    """
    p = Path(path).expanduser()
    if p.is_file() and p.name.lower().endswith((".mat", ".npz")):
        return [p]
    if not p.exists() and p.name.lower().endswith((".mat", ".npz")):
        raise FileFormatError(f"model file {str(p)!r} does not exist or is not a file")
    return sorted(matrix_market_set(p)[2].values())
