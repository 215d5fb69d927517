"""Readers and writers of full-order models.

* :func:`load_mat` reads the M.E.S.S. layout (a .mat file with M, D, K, G and
  a first-order realization E, A, B, C), MATLAB v4/v5/v7 through scipy and v7.3
  (HDF5) through h5py (:mod:`.mat73`). M.E.S.S. stores D and K with the
  opposite sign (``A = [[0, I, 0], [K, D, -G^T], [G, 0, 0]]``), so the loader
  negates them; F is the velocity block of B, L the position block of C
  (:mod:`.layout`).
* :func:`~morsuite.models.mtx.load_mtx` reads Matrix Market sets (:mod:`.mtx`).
* :func:`save_npz` / :func:`load_npz`: a plain npz layout (CSR parts of M, D, K,
  G; dense F, L; name and band), read with ``allow_pickle=False``.
* :func:`load` picks the reader from the path.
"""

from __future__ import annotations

import json
import zipfile
import zlib
from pathlib import Path

import numpy as np
import scipy.io as sio
import scipy.sparse as sp

from ..errors import FileFormatError, InputError
from ..modelfiles import MTX_ENDINGS
from ..utils import atomic_path
from .index3 import Index3Model
from .layout import check_sign_option, check_stiffness_sign, existing, input_matrix, output_matrix, to_physical
from .mat73 import is_hdf5, read_mat73
from .mtx import load_mtx

__all__ = ["load_mat", "load_npz", "save_npz", "load", "load_mtx"]

NPZ_FORMAT = "morsuite-index3-v1"
#: the variables of a .mat file the loader reads (others, e.g. the projectors Pl, Pr, are skipped)
MAT_VARIABLES = ("M", "D", "K", "G", "F", "L", "B", "C", "A")


def _read_mat(p: Path):
    """(variables, names of all variables) of a MATLAB file, v7.3 (HDF5) or older."""
    if is_hdf5(p):
        return read_mat73(p, MAT_VARIABLES)
    try:
        found = sorted(name for name, _, _ in sio.whosmat(str(p)))
        data = sio.loadmat(str(p), variable_names=[k for k in MAT_VARIABLES if k in found])
    except NotImplementedError as exc:  # scipy's answer to a v7.3 header; is_hdf5 found no HDF5 body
        raise FileFormatError(f"{p}: says MATLAB v7.3 (HDF5) but holds no HDF5 data (truncated or damaged)") from exc
    except Exception as exc:  # scipy raises several types on corrupt files
        raise FileFormatError(f"{p}: not a readable .mat file ({type(exc).__name__}: {exc})") from exc
    return {k: v for k, v in data.items() if not k.startswith("__")}, found


def load_mat(path, *, sign: str = "mess", name: str | None = None, band=(1e-2, 1.0),
             check_realization: bool = True, check_sign: bool = True) -> Index3Model:
    """Load a second-order index-3 model from a M.E.S.S. .mat file.

    Parameters
    ----------
    path : path-like
        MATLAB v4/v5/v7 or v7.3 (HDF5) file with the variables M, D, K, G and
        either F and L or the first-order B and C (E and A optional; other
        variables are not read).
    sign : {"mess", "physical"}
        ``"mess"``: D and K are stored negated (the M.E.S.S. convention, see
        models.md) and are negated on loading. ``"physical"``: taken as stored.
    name : str, optional
        Model name (default: the file's stem).
    band : (float, float)
        Default frequency band in rad/s (default (1e-2, 1)).
    check_realization : bool
        If the file holds A, check that its (2, 1) block equals the stored K,
        which is what the M.E.S.S. convention implies (default True).
    check_sign : bool
        Refuse a stiffness whose diagonal, in the physical convention, is
        nowhere positive and somewhere negative: the sign convention was the
        other one (default True; see :mod:`.layout`).

    Cost: reading the file; one sparse LU of M for the constraint check.

    Raises
    ------
    FileFormatError
        Missing or unreadable file, a missing matrix (named), a B or C that is
        not the second-order layout, or a file that contradicts the sign
        convention.
    """
    p = existing(path)
    check_sign_option(sign)
    data, found = _read_mat(p)
    missing = [k for k in ("M", "D", "K", "G") if k not in data]
    if missing:
        raise FileFormatError(f"{p}: missing matrix {', '.join(missing)} (found {found})")
    M, Df, Kf, G = (sp.csr_matrix(data[k]) if sp.issparse(data[k]) else data[k] for k in ("M", "D", "K", "G"))
    n1 = M.shape[0]
    if "F" in data and "L" in data:
        F, L = input_matrix(data["F"], n1, p, "F"), output_matrix(data["L"], n1, p, "L")
    else:
        missing = [k for k in ("B", "C") if k not in data]
        if missing:
            raise FileFormatError(f"{p}: missing matrix {', '.join(missing)} (needed for F and L, or store F and L)")
        F, L = input_matrix(data["B"], n1, p, "B"), output_matrix(data["C"], n1, p, "C")
    if check_realization and "A" in data:
        # the realization fixes the sign: A[n1:2n1, :n1] is K_file (M.E.S.S.) or -K (physical)
        A = sp.csr_matrix(data["A"])
        expected = sp.csr_matrix(Kf) if sign == "mess" else -sp.csr_matrix(Kf)
        if A.shape[0] >= 2 * n1 and abs(A[n1:2 * n1, :n1] - expected).max() != 0:
            other = "physical" if sign == "mess" else "mess"
            raise FileFormatError(f"{p}: block A[n1:2n1, :n1] differs from {'K' if sign == 'mess' else '-K'}: the file does not follow the sign={sign!r} convention (try sign={other!r})")
    Df, Kf = to_physical(Df, Kf, sign)
    if check_sign:
        check_stiffness_sign(Kf, sign, p)
    return Index3Model(M, Df, Kf, G, F, L, name=name or p.stem, band=band)


def save_npz(model: Index3Model, path) -> Path:
    """Write ``model`` to ``path`` in the plain npz layout (atomic, no pickles)."""
    if not isinstance(model, Index3Model):
        raise InputError(f"model must be an Index3Model; got {type(model).__name__}")
    arrays = {"format": np.array(NPZ_FORMAT), "name": np.array(model.name),
              "band": np.asarray(model.band, dtype=float), "F": model.F, "L": model.L}
    for key in ("M", "D", "K", "G"):
        X = sp.csr_matrix(getattr(model, key))
        arrays[f"{key}_data"] = X.data
        arrays[f"{key}_indices"] = X.indices
        arrays[f"{key}_indptr"] = X.indptr
        arrays[f"{key}_shape"] = np.asarray(X.shape, dtype=np.int64)
    path = Path(path)
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)
    return path


def load_npz(path, *, check_constraints: bool = True) -> Index3Model:
    """Read a model written by :func:`save_npz`."""
    p = existing(path)
    try:
        with np.load(p, allow_pickle=False) as z:
            content = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError) as exc:
        raise FileFormatError(f"{p}: not a readable npz file ({type(exc).__name__}: {exc})") from exc
    if str(content.get("format", "")) != NPZ_FORMAT:
        raise FileFormatError(f"{p}: entry 'format' is missing or not {NPZ_FORMAT!r}")
    mats = {}
    for key in ("M", "D", "K", "G"):
        parts = [f"{key}_{x}" for x in ("data", "indices", "indptr", "shape")]
        missing = [k for k in parts if k not in content]
        if missing:
            raise FileFormatError(f"{p}: missing key {', '.join(missing)} (matrix {key})")
        try:
            mats[key] = sp.csr_matrix((content[parts[0]], content[parts[1]], content[parts[2]]),
                                      shape=tuple(int(x) for x in content[parts[3]]))
        except ValueError as exc:
            raise FileFormatError(f"{p}: matrix {key} is corrupt ({exc})") from exc
    for key in ("F", "L"):
        if key not in content:
            raise FileFormatError(f"{p}: missing key {key}")
    return Index3Model(mats["M"], mats["D"], mats["K"], mats["G"], content["F"], content["L"],
                       name=str(content.get("name", p.stem)),
                       band=tuple(content["band"]) if "band" in content else (1e-2, 1.0),
                       check_constraints=check_constraints)


def load(path, **kwargs) -> Index3Model:
    """Load a model, choosing the reader from the path.

    * ``*.mat``: :func:`load_mat` (M.E.S.S. layout; MATLAB v5/v7 or v7.3);
    * ``*.npz``: :func:`load_npz`;
    * a directory, a ``*.mtx`` file, a file whose content starts with
      ``%%MatrixMarket`` (``gyro.M``), or a stem whose set exists (``data/gyro``):
      :func:`~morsuite.models.mtx.load_mtx`.

    Keyword arguments go to that reader.
    """
    p = Path(path).expanduser()
    low = p.name.lower()
    if low.endswith(".mat"):
        return load_mat(p, **kwargs)
    if low.endswith(".npz"):
        return load_npz(p, **kwargs)
    if p.is_dir() or low.endswith(MTX_ENDINGS) or not p.exists():
        return load_mtx(p, **kwargs)  # a missing path may be the stem of a set
    if p.is_file():
        with open(p, "rb") as fh:
            if fh.read(14).lower() == b"%%matrixmarket":
                return load_mtx(p, **kwargs)
    raise FileFormatError(f"model file {str(p)!r}: unknown extension {p.suffix!r}; expected .mat, .npz, "
                          ".mtx or a Matrix Market set (a directory, a stem, or a file such as NAME.M)")


def describe(model: Index3Model) -> str:
    """One-line JSON summary (used by the CLI)."""
    return json.dumps(model.summary())
