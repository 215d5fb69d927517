r"""Reduced models as files: ``.npz`` and MATLAB ``.mat``, a JSON provenance sidecar, and the model's hash.

:func:`save_rom` writes ``STEM.npz`` and ``STEM.mat`` (each atomically) and the sidecar
``STEM.json``; :func:`load_rom` (also ``morsuite.load_rom``) reads either file back, bit for
bit, checks it against the SHA-256 its sidecar recorded and attaches the sidecar as
``rom.provenance``. ``morsuite reduce --save`` and ``morsuite verify`` use them.

Variables (the same names in both files; MATLAB/Octave: ``load('STEM.mat')``)

=====================  ==============================================================
``kind``               ``'second-order'`` or ``'first-order'`` (a char row in MATLAB)
second order, order r  ``M``, ``D``, ``K`` (r x r), ``F`` (r x m), ``L`` (p x r):
                       :math:`M\ddot q + D\dot q + Kq = Fu`, :math:`y = Lq`
first order, n states  ``E``, ``A`` (n x n), ``B`` (n x m), ``C`` (p x n), ``D`` (p x m):
                       :math:`E\dot x = Ax + Bu`, :math:`y = Cx + Du`
=====================  ==============================================================

``D`` is the damping matrix of a second-order model and the feedthrough of a first-order
one. In MATLAB, a second-order model is ``mechss(M, D, K, F, L)`` (R2020b and later), or in
first-order form (MATLAB and Octave's control package)::

    r = size(M, 1);  m = size(F, 2);  p = size(L, 1);
    sys = dss([zeros(r) eye(r); -K -D], [zeros(r, m); F], [L zeros(p, r)], zeros(p, m), ...
              blkdiag(eye(r), M));

and a first-order one ``dss(A, B, C, D, E)``. The .mat file is MATLAB v5 (uncompressed),
which MATLAB, Octave and :func:`scipy.io.loadmat` read; the matrices are doubles.

The sidecar (JSON, strict: no NaN or infinity, which are written as the strings ``"nan"``,
``"inf"``): ``format`` (:data:`FORMAT`), ``format_version``, ``kind``, ``order``, ``states``,
``m``, ``p``, ``variables``, ``files`` (per format: the file's name, its SHA-256 and size)
and ``provenance``, the caller's record (:func:`provenance_of` makes the one the command line
and the study runner write: the model with its :func:`model_hash`, the method and its
options, the errors with their certificates, band, LUs, time, morsuite version, the UTC time
of writing).
"""

from __future__ import annotations

import datetime
import hashlib
import json
from pathlib import Path

import numpy as np

from . import __version__
from .errors import FileFormatError, InputError, OptionError
from .rom import FirstOrderROM, SecondOrderROM, load_rom as _load_file
from .utils import atomic_write_text, strict_json, to_plain

__all__ = ["FORMAT", "FORMAT_VERSION", "FORMATS", "VARIABLES", "ERROR_KEYS", "save_rom", "load_rom",
           "read_sidecar", "model_hash", "provenance_of", "grid_omega"]

#: the sidecar's ``format`` value
FORMAT = "morsuite-rom"
#: the sidecar's ``format_version`` this code writes (and the newest it reads)
FORMAT_VERSION = 1
#: the file formats :func:`save_rom` writes, in the order :func:`load_rom` looks for them by stem
FORMATS = ("npz", "mat")
#: the variables of each kind of reduced model, as stored
VARIABLES = {SecondOrderROM.kind: SecondOrderROM._fields, FirstOrderROM.kind: FirstOrderROM._fields}
_BAND_KEYS = ("max_abs_error", "max_rel_error", "band_peak")
_H2_KEYS = ("h2_error", "h2_rel_error", "h2_norm", "h2_floor", "h2_norm_floor", "h2_trusted", "h2_route",
            "h2_lu_count", "h2_time_s")
_HINF_KEYS = ("hinf_error", "hinf_rel_error", "hinf_norm", "hinf_upper_bound", "hinf_certified", "hinf_trusted",
              "hinf_norm_upper_bound", "hinf_norm_certified", "hinf_route", "hinf_peak_frequency", "hinf_lu_count",
              "hinf_time_s")
#: the keys :func:`provenance_of` takes in ``errors`` (those of ``morsuite reduce --json`` and
#: :func:`morsuite.analysis.error_norms`)
ERROR_KEYS = _BAND_KEYS + _H2_KEYS + _HINF_KEYS + ("norm_options", "norm_warnings", "norms")


def _stem(path) -> Path:
    """``path`` without a .npz / .mat / .json ending (any other ending is part of the stem)."""
    path = Path(path)
    return path.with_suffix("") if path.suffix in (".npz", ".mat", ".json") else path


def _with(stem: Path, ending: str) -> Path:
    return stem.with_name(stem.name + ending)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _json_text(obj, name: str) -> str:
    try:
        return json.dumps(strict_json(to_plain(obj)), allow_nan=False, indent=1) + "\n"
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} is not JSON data ({exc})") from exc


def save_rom(rom, path, *, provenance=None, formats=FORMATS) -> list[Path]:
    """Write a reduced model as ``STEM.npz`` and ``STEM.mat`` with the sidecar ``STEM.json``.

    Parameters
    ----------
    rom : SecondOrderROM or FirstOrderROM
    path : str or Path
        The stem, or a path ending in .npz or .mat (the ending is dropped; any other
        ending is part of the stem: ``rom.v2`` writes ``rom.v2.npz``). Directories are made.
    provenance : dict, optional
        JSON data stored as the sidecar's ``provenance`` (:func:`provenance_of` makes the
        one morsuite writes); None (default) records none.
    formats : sequence of {"npz", "mat"}
        The files to write (default both).

    Returns
    -------
    list of Path
        The files written: the data files in the order of ``formats``, then the sidecar.

    Raises
    ------
    InputError
        ``rom`` is not a reduced model, ``formats`` is empty or has an unknown name,
        ``provenance`` is not JSON data, or ``STEM.json`` exists and is not a sidecar (it is
        not overwritten).

    Notes
    -----
    Each file is written to a temporary name and renamed (:func:`morsuite.utils.atomic_path`),
    the data files first, so an interrupted call leaves old or new files, and a sidecar
    whose hashes no longer match refuses a changed file on loading. Values are stored
    exactly (float64 in both formats). Cost: writing and hashing the ``r^2`` numbers.
    """
    if getattr(rom, "kind", None) not in VARIABLES or not hasattr(rom, "save"):
        raise InputError(f"rom must be a SecondOrderROM or FirstOrderROM; got {type(rom).__name__}")
    if isinstance(formats, str):
        formats = (formats,)
    formats = tuple(formats)
    bad = [f for f in formats if f not in FORMATS]
    if not formats or bad or len(set(formats)) != len(formats):
        raise InputError(f"formats must be distinct names out of {', '.join(FORMATS)}; got {list(formats)}")
    if provenance is not None and not isinstance(provenance, dict):
        raise InputError(f"provenance must be a dict or None; got {type(provenance).__name__}")
    stem = _stem(path)
    side = _with(stem, ".json")
    if side.exists():
        try:
            read_sidecar(side)
        except FileFormatError as exc:
            raise InputError(f"path {str(path)!r}: {side} exists and is not a morsuite ROM sidecar; it is not "
                             f"overwritten (choose another path) [{exc}]") from exc
    record = {"format": FORMAT, "format_version": FORMAT_VERSION, "kind": rom.kind, "order": int(rom.order),
              "states": int(rom.states), "m": int(rom.m), "p": int(rom.p), "variables": list(VARIABLES[rom.kind]),
              "files": {}, "provenance": provenance}
    _json_text(record, "provenance")  # not JSON data: refused before any file is written
    written = []
    for fmt in formats:
        target = rom.save(_with(stem, "." + fmt))
        record["files"][fmt] = {"name": target.name, "sha256": _sha256(target), "bytes": target.stat().st_size}
        written.append(target)
    atomic_write_text(side, _json_text(record, "provenance"))
    return written + [side]


def read_sidecar(path) -> dict:
    """The sidecar ``STEM.json`` of a reduced model (``path``: the sidecar, a data file or the stem).

    Raises
    ------
    FileFormatError
        Naming the sidecar: missing, not JSON, not a morsuite ROM sidecar, or written by a
        newer format version.
    """
    side = _with(_stem(path), ".json")
    if not side.is_file():
        raise FileFormatError(f"sidecar {str(side)!r} does not exist")
    try:
        data = json.loads(side.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise FileFormatError(f"sidecar {str(side)!r} is not readable JSON ({exc})") from exc
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise FileFormatError(f"sidecar {str(side)!r} is not a morsuite ROM sidecar (no \"format\": \"{FORMAT}\")")
    version = data.get("format_version")
    if not isinstance(version, int) or version < 1 or version > FORMAT_VERSION:
        raise FileFormatError(f"sidecar {str(side)!r}: format_version {version!r} is not one this morsuite reads "
                              f"(1 to {FORMAT_VERSION}; a newer morsuite wrote it?)")
    if not isinstance(data.get("files"), dict):
        raise FileFormatError(f"sidecar {str(side)!r}: entry 'files' missing")
    return data


def load_rom(path):
    """Read a reduced model written by :func:`save_rom` (or ``rom.save``), bit for bit.

    Parameters
    ----------
    path : str or Path
        ``STEM.npz``, ``STEM.mat``, the sidecar ``STEM.json`` or the stem (then ``STEM.npz``
        is read if it exists, else ``STEM.mat``).

    Returns
    -------
    SecondOrderROM or FirstOrderROM
        With ``provenance``: the sidecar (dict) when ``STEM.json`` exists, else None.

    Raises
    ------
    FileFormatError
        Naming the file and what is wrong: no such file, unreadable or unknown content
        (:func:`morsuite.rom.load_rom`), a sidecar that is not one, does not list the file,
        records another SHA-256 (the file changed after it was written) or another kind,
        order or size than the file holds. Cost: reading and hashing the file.
    """
    p = Path(path)
    stem = _stem(p)
    if p.suffix in (".npz", ".mat"):
        file = p
    else:
        found = [_with(stem, "." + f) for f in FORMATS if _with(stem, "." + f).is_file()]
        if not found:
            raise FileFormatError(f"ROM file {str(path)!r}: neither {_with(stem, '.npz')} nor "
                                  f"{_with(stem, '.mat')} exists")
        file = found[0]
    side = _with(stem, ".json")
    record = read_sidecar(side) if side.exists() else None
    if record is not None:
        entry = record["files"].get(file.suffix[1:])
        if not isinstance(entry, dict) or entry.get("name") != file.name:
            raise FileFormatError(f"ROM file {str(file)!r}: its sidecar {str(side)!r} does not list it (another "
                                  "save wrote the sidecar; save again, or remove the sidecar)")
        if file.is_file() and _sha256(file) != entry.get("sha256"):
            raise FileFormatError(f"ROM file {str(file)!r}: SHA-256 {_sha256(file)[:16]}... differs from "
                                  f"{str(entry.get('sha256'))[:16]}... recorded in {str(side)!r}: the file was "
                                  "changed or corrupted after it was written")
    rom = _load_file(file)
    if record is not None:
        got = {"kind": rom.kind, "order": rom.order, "states": rom.states, "m": rom.m, "p": rom.p}
        diff = [f"{k} {got[k]!r} (sidecar: {record.get(k)!r})" for k in got if record.get(k) != got[k]]
        if diff:
            raise FileFormatError(f"ROM file {str(file)!r} does not match its sidecar {str(side)!r}: "
                                  + ", ".join(diff))
    rom.provenance = record
    return rom


def model_hash(fom) -> str:
    """SHA-256 of a model's matrices: content identity, whatever built it.

    Hashed, in this order: M, D, K, G as canonical CSR (duplicates summed, explicit zeros
    dropped, column indices sorted; the shape, then ``indptr`` and ``indices`` as
    little-endian int64 and ``data`` as little-endian float64 with -0.0 written as 0.0), then
    F and L as dense float64 (shape, then the values row by row). Two models have equal
    hashes when their matrices are equal entry by entry (names, bands, storage order, index
    types and LU settings aside). Unlike :meth:`morsuite.models.Index3Model.digest`, which
    hashes the matrices as stored (the key of caches), it does not depend on how the model
    was assembled. Kept in ``fom.cache``. Cost: one copy and pass over the matrices
    (measured at fem_block(n1=20000): ``docs/design/romfiles.md``).

    Raises
    ------
    InputError
        ``fom`` lacks a matrix M, D, K, G, F or L.
    """
    import scipy.sparse as sp

    cache = getattr(fom, "cache", None)
    if isinstance(cache, dict) and "model_hash" in cache:
        return cache["model_hash"]
    missing = [k for k in ("M", "D", "K", "G", "F", "L") if getattr(fom, k, None) is None]
    if missing:
        raise InputError(f"fom must be a model with matrices M, D, K, G, F, L; {type(fom).__name__} lacks "
                         f"{', '.join(missing)}")
    h = hashlib.sha256(b"morsuite model hash 1\0")
    for name in ("M", "D", "K", "G"):
        X = sp.csr_matrix(getattr(fom, name), dtype=np.float64, copy=True)
        X.sum_duplicates()  # also sorts the indices
        X.eliminate_zeros()
        h.update(f"{name} csr {X.shape[0]} {X.shape[1]}\0".encode())
        for a, t in ((X.indptr, "<i8"), (X.indices, "<i8"), (X.data + 0.0, "<f8")):
            h.update(np.ascontiguousarray(a, dtype=t).tobytes())
    for name in ("F", "L"):
        X = getattr(fom, name)
        X = np.atleast_2d(X.toarray() if sp.issparse(X) else np.asarray(X, dtype=np.float64))
        h.update(f"{name} dense {X.shape[0]} {X.shape[1]}\0".encode())
        h.update(np.ascontiguousarray(X + 0.0, dtype="<f8").tobytes())
    out = h.hexdigest()
    if isinstance(cache, dict):
        cache["model_hash"] = out
    return out


def _grid_record(grid):
    """``{"lo", "hi", "n", "spacing": "log"}`` of a log grid (given as (lo, hi, n) or its array), else
    ``{"omega": [...]}``."""
    if isinstance(grid, (tuple, list)) and len(grid) == 3 and not isinstance(grid[2], float):
        lo, hi, n = float(grid[0]), float(grid[1]), int(grid[2])
        if not (0 < lo < hi < np.inf) or n < 1:
            raise InputError(f"grid must be (lo, hi, n) with 0 < lo < hi and n >= 1; got {grid!r}")
        return {"lo": lo, "hi": hi, "n": n, "spacing": "log"}
    w = np.asarray(grid, dtype=float)
    if w.ndim != 1 or w.size == 0 or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InputError(f"grid must be (lo, hi, n) or a 1-D array of frequencies >= 0; got {grid!r}")
    if w.size > 1 and w[0] > 0 and np.array_equal(w, np.logspace(np.log10(w[0]), np.log10(w[-1]), w.size)):
        return {"lo": float(w[0]), "hi": float(w[-1]), "n": int(w.size), "spacing": "log"}
    return {"omega": w.tolist()}


def grid_omega(record) -> np.ndarray:
    """The frequencies (rad/s) of a grid record of :func:`provenance_of`: ``np.logspace(log10(lo),
    log10(hi), n)``, as ``morsuite reduce`` and the study runner make them, or the listed ``omega``."""
    if not isinstance(record, dict):
        raise InputError(f"grid record must be a dict; got {type(record).__name__}")
    if "omega" in record:
        return np.asarray(record["omega"], dtype=float)
    try:
        lo, hi, n = float(record["lo"]), float(record["hi"]), int(record["n"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"grid record needs lo, hi, n or omega; got {record!r}") from exc
    return np.logspace(np.log10(lo), np.log10(hi), n)


def _get(errors, key):
    return to_plain(errors.get(key))


def _errors_record(errors, grid):
    e = dict(errors or {})
    unknown = sorted(set(e) - set(ERROR_KEYS))
    if unknown:
        raise OptionError(f"errors has unknown key(s) {', '.join(map(repr, unknown))}; valid: {', '.join(ERROR_KEYS)}")
    band = None
    if e.get("max_abs_error") is not None:
        if grid is None:
            raise InputError("grid is required with band errors (max_abs_error): the frequencies they were taken on")
        peak = _get(e, "band_peak")
        band = {"grid": _grid_record(grid), "response": "lu", "max_abs_error": _get(e, "max_abs_error"),
                "max_rel_error": _get(e, "max_rel_error"), "peak": peak,
                "max_error_rel_peak": (float(e["max_abs_error"]) / float(peak) if peak else None)}
    opts = e.get("norm_options") or {}
    h2 = hinf = None
    if e.get("h2_error") is not None:
        h2 = {"error": _get(e, "h2_error"), "rel_error": _get(e, "h2_rel_error"), "norm": _get(e, "h2_norm"),
              "floor": _get(e, "h2_floor"), "norm_floor": _get(e, "h2_norm_floor"), "trusted": _get(e, "h2_trusted"),
              "route": _get(e, "h2_route"), "lu_count": _get(e, "h2_lu_count"), "time_s": _get(e, "h2_time_s"),
              "options": to_plain(opts.get("h2"))}
    if e.get("hinf_error") is not None:
        hinf = {"lower_bound": _get(e, "hinf_error"), "upper_bound": _get(e, "hinf_upper_bound"),
                "certified": _get(e, "hinf_certified"), "rel_error": _get(e, "hinf_rel_error"),
                "norm": _get(e, "hinf_norm"), "norm_upper_bound": _get(e, "hinf_norm_upper_bound"),
                "norm_certified": _get(e, "hinf_norm_certified"), "route": _get(e, "hinf_route"),
                "peak_frequency": _get(e, "hinf_peak_frequency"), "lu_count": _get(e, "hinf_lu_count"),
                "time_s": _get(e, "hinf_time_s"), "options": to_plain(opts.get("hinf"))}
    note = e.get("norms") or ("computed" if h2 or hinf else "not computed")
    return {"band": band, "h2": h2, "hinf": hinf, "norms": note, "norm_warnings": list(e.get("norm_warnings") or [])}


def provenance_of(fom, method, options, info, errors=None, band=None, grid=None, *, source=None, cost=None,
                  extra=None) -> dict:
    """The provenance record of a reduced model, as ``morsuite reduce --save`` and the study runner write it.

    Parameters
    ----------
    fom : Index3Model
        The full model (its name, sizes, band and :func:`model_hash`).
    method : str
        The reducer's name.
    options : dict or None
        The options as given; the resolved ones (defaults filled in) are taken from ``info``.
    info : dict
        The reducer's ``info`` (``r``, ``r_requested``, ``kind``, ``states``, ``converged``,
        ``status``, ``iterations``, ``stable``, ``lu_count``, ``lu_count_shared``, ``time_s``,
        ``options``, ``warnings``, ``lu_backend``; missing ones are recorded as None).
    errors : dict, optional
        Flat errors with the names of ``morsuite reduce --json`` and
        :func:`morsuite.analysis.error_norms` (:data:`ERROR_KEYS`): band ``max_abs_error``,
        ``max_rel_error``, ``band_peak`` (:math:`\\max_\\omega \\sigma_{\\max}(T)` on the grid);
        ``h2_*`` (value, relative value, norm, ``h2_floor``, ``h2_norm_floor``, trusted, route,
        LUs, time), ``hinf_*`` (the lower bound ``hinf_error``, ``hinf_upper_bound``,
        ``hinf_certified``, the model's norm and its bound, peak frequency, LUs, time),
        ``norm_options`` (per kind, as used), ``norm_warnings``, ``norms`` (a note, e.g. why
        they were not computed). Unknown keys are refused. None or missing norms: recorded as
        null.
    band : (float, float), optional
        The band of the comparison (default the model's).
    grid : (lo, hi, n) or array_like, optional
        The frequencies of the band errors (required with them): log-spaced as
        :func:`grid_omega` remakes them, else listed.
    source : str, optional
        The model as the caller named it (a catalog spec or a path).
    cost : dict, optional
        Further cost figures merged into ``cost`` (e.g. a study's ``lu_count_standalone``).
    extra : dict, optional
        Further top-level entries (e.g. a study's name and scene, a tolerance search's
        record); a key of the record itself is refused.

    Returns
    -------
    dict
        ``model`` (``name``, ``source``, ``hash``, ``n1``, ``n2``, ``m``, ``p``, ``band``),
        ``method``, ``options``, ``options_resolved``, ``r``, ``r_requested``, ``kind``,
        ``states``, ``outcome`` (``converged``, ``status``, ``iterations``, ``stable``,
        ``warnings``), ``cost`` (``lu_count``, ``lu_count_shared``, ``time_s``, ``lu_backend``),
        ``band``, ``errors`` (``band``: grid, ``max_abs_error``, ``max_rel_error``, ``peak``,
        ``max_error_rel_peak``; ``h2``: ``error``, ``floor``, ``norm``, ``norm_floor``,
        ``trusted``, ...; ``hinf``: ``lower_bound``, ``upper_bound``, ``certified``, ``norm``,
        ``norm_upper_bound``, ...; ``norms``), ``morsuite`` (version), ``created_utc``.
        Plain JSON data. Cost: :func:`model_hash`.
    """
    if not isinstance(info, dict):
        raise InputError(f"info must be a reducer's info dict; got {type(info).__name__}")
    if options is not None and not isinstance(options, dict):
        raise InputError(f"options must be a dict or None; got {type(options).__name__}")
    for name, value in (("cost", cost), ("extra", extra)):
        if value is not None and not isinstance(value, dict):
            raise InputError(f"{name} must be a dict or None; got {type(value).__name__}")
    lo, hi = (float(b) for b in (band if band is not None else fom.band))
    backend = info.get("lu_backend")
    record = {
        "model": {"name": getattr(fom, "name", None), "source": None if source is None else str(source),
                  "hash": model_hash(fom), "n1": int(fom.n1), "n2": int(fom.n2), "m": int(fom.m), "p": int(fom.p),
                  "band": [float(b) for b in fom.band]},
        "method": str(method), "options": to_plain(dict(options or {})), "options_resolved": info.get("options"),
        "r": info.get("r"), "r_requested": info.get("r_requested"), "kind": info.get("kind"),
        "states": info.get("states"),
        "outcome": {k: info.get(k) for k in ("converged", "status", "iterations", "stable", "warnings")},
        "cost": {"lu_count": info.get("lu_count"), "lu_count_shared": info.get("lu_count_shared"),
                 "time_s": info.get("time_s"),
                 "lu_backend": backend.get("backend", backend.get("name")) if isinstance(backend, dict) else backend,
                 **(cost or {})},
        "band": [lo, hi],
        "errors": _errors_record(errors, grid),
        "morsuite": __version__,
        "created_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }
    clash = sorted(set(extra or {}) & set(record))
    if clash:
        raise InputError(f"extra may not replace the record's own key(s) {', '.join(map(repr, clash))}")
    record.update(extra or {})
    return to_plain(record)
