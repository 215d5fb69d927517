"""Readers and writers of full-order models.

* :func:`load_mat` reads the M.E.S.S. layout (MATLAB v5 .mat with M, D, K, G and
  a first-order realization E, A, B, C). M.E.S.S. stores D and K with the
  opposite sign (``A = [[0, I, 0], [K, D, -G^T], [G, 0, 0]]``), so the loader
  negates them; F is the velocity block of B, L the position block of C.
* :func:`save_npz` / :func:`load_npz`: a plain npz layout (CSR parts of M, D, K,
  G; dense F, L; name and band), read with ``allow_pickle=False``.
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
from ..utils import atomic_path
from .index3 import Index3Model

__all__ = ["load_mat", "load_npz", "save_npz", "load"]

NPZ_FORMAT = "morsuite-index3-v1"


def _existing(path) -> Path:
    p = Path(path)
    if not p.is_file():
        raise FileFormatError(f"model file {str(p)!r} does not exist or is not a file")
    return p


def load_mat(path, *, sign: str = "mess", name: str | None = None, band=(1e-2, 1.0),
             check_realization: bool = True) -> Index3Model:
    """Load a second-order index-3 model from a M.E.S.S. .mat file.

    Parameters
    ----------
    path : path-like
        MATLAB v4/v5/v7 file with entries M, D, K, G, B, C (E and A optional).
    sign : {"mess", "physical"}
        ``"mess"``: D and K are stored negated (the M.E.S.S. convention, see
        models.md) and are negated on loading. ``"physical"``: taken as stored.
    check_realization : bool
        If the file holds A, check that its (2, 1) block equals the stored K,
        which is what the M.E.S.S. convention implies.

    Raises
    ------
    FileFormatError
        Missing or unreadable file, a missing matrix (named), or a realization
        that contradicts the sign convention.
    """
    p = _existing(path)
    if sign not in ("mess", "physical"):
        raise InputError(f"sign must be 'mess' or 'physical'; got {sign!r}")
    try:
        data = sio.loadmat(str(p))
    except NotImplementedError as exc:  # v7.3 (HDF5)
        raise FileFormatError(f"{p}: MATLAB v7.3 (HDF5) files are not supported; save with -v7") from exc
    except Exception as exc:  # scipy raises several types on corrupt files
        raise FileFormatError(f"{p}: not a readable .mat file ({type(exc).__name__}: {exc})") from exc
    missing = [k for k in ("M", "D", "K", "G") if k not in data]
    if missing:
        raise FileFormatError(f"{p}: missing matrix {', '.join(missing)} (found {sorted(k for k in data if not k.startswith('__'))})")
    M, Df, Kf, G = (sp.csr_matrix(data[k]) if sp.issparse(data[k]) else data[k] for k in ("M", "D", "K", "G"))
    n1 = M.shape[0]
    if "F" in data and "L" in data:
        F, L = data["F"], data["L"]
    else:
        missing = [k for k in ("B", "C") if k not in data]
        if missing:
            raise FileFormatError(f"{p}: missing matrix {', '.join(missing)} (needed for F and L, or store F and L)")
        B, C = data["B"], data["C"]
        B = B.toarray() if sp.issparse(B) else np.asarray(B)
        C = C.toarray() if sp.issparse(C) else np.asarray(C)
        if B.shape[0] < 2 * n1 or C.shape[1] < n1:
            raise FileFormatError(f"{p}: B has {B.shape[0]} rows and C {C.shape[1]} columns; expected at least 2 n1 = {2 * n1} and n1 = {n1}")
        F, L = B[n1:2 * n1], C[:, :n1]
        if np.any(B[:n1] != 0):
            raise FileFormatError(f"{p}: B has nonzeros in its position block; not the M.E.S.S. second-order layout")
    if check_realization and "A" in data:
        # the realization fixes the sign: A[n1:2n1, :n1] is K_file (M.E.S.S.) or -K (physical)
        A = sp.csr_matrix(data["A"])
        expected = sp.csr_matrix(Kf) if sign == "mess" else -sp.csr_matrix(Kf)
        if A.shape[0] >= 2 * n1 and abs(A[n1:2 * n1, :n1] - expected).max() != 0:
            other = "physical" if sign == "mess" else "mess"
            raise FileFormatError(f"{p}: block A[n1:2n1, :n1] differs from {'K' if sign == 'mess' else '-K'}: the file does not follow the sign={sign!r} convention (try sign={other!r})")
    if sign == "mess":
        Df, Kf = -Df, -Kf
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
    p = _existing(path)
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
    """Load by extension: ``.mat`` (M.E.S.S.) or ``.npz`` (morsuite)."""
    p = Path(path)
    if p.suffix == ".mat":
        return load_mat(p, **kwargs)
    if p.suffix == ".npz":
        return load_npz(p, **kwargs)
    raise FileFormatError(f"model file {str(p)!r}: unknown extension {p.suffix!r}; expected .mat or .npz")


def describe(model: Index3Model) -> str:
    """One-line JSON summary (used by the CLI)."""
    return json.dumps(model.summary())
