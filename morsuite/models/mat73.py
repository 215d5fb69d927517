"""MATLAB v7.3 .mat files (HDF5), read with h5py.

A v7.3 file is an HDF5 file behind a 512-byte user block whose text starts with
``MATLAB 7.3 MAT-file``. Each variable is an object at the root carrying the
attribute ``MATLAB_class`` (``double``, ``logical``, ...):

* a dense array is a dataset holding the column-major MATLAB array, so HDF5
  (row-major) sees its transpose: a MATLAB p x q matrix is a (q, p) dataset;
  complex arrays are compound datasets with fields ``real`` and ``imag``;
* a sparse matrix is a group with the attribute ``MATLAB_sparse`` = number of
  rows and the compressed-column parts ``data`` (values), ``ir`` (row indices,
  0-based) and ``jc`` (column pointers, ncols + 1 entries); an all-zero sparse
  matrix may have no ``data`` and ``ir``;
* an empty array is a dataset with the attribute ``MATLAB_empty`` = 1 whose
  content is its dimensions;
* cells, structs and strings use object references and other classes: none
  of them is a matrix of a model, and they are refused by name.

Only the requested variables are read (a M.E.S.S. file also holds the spectral
projectors Pl, Pr, as large as A).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import FileFormatError

__all__ = ["HDF5_SIGNATURE", "is_hdf5", "read_mat73"]

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
NUMERIC_CLASSES = ("double", "single", "logical", "int8", "uint8", "int16", "uint16", "int32", "uint32",
                   "int64", "uint64")


def is_hdf5(path) -> bool:
    """True if ``path`` holds an HDF5 superblock at offset 0, 512, 1024, 2048, ... (the user-block sizes)."""
    with open(path, "rb") as fh:
        offset = 0
        while True:
            fh.seek(offset)
            head = fh.read(8)
            if len(head) < 8:
                return False
            if head == HDF5_SIGNATURE:
                return True
            offset = 512 if offset == 0 else 2 * offset


def _text(value) -> str:
    if isinstance(value, np.ndarray):
        value = value.flat[0] if value.size else b""
    return value.decode("ascii", "replace") if isinstance(value, (bytes, np.bytes_)) else str(value)


def _complex(a):
    """Compound ``real``/``imag`` data as complex; anything else unchanged."""
    if a.dtype.names and {"real", "imag"} <= set(a.dtype.names):
        return a["real"] + 1j * a["imag"]
    return a


def _variable(obj, where, key):
    import h5py

    cls = _text(obj.attrs.get("MATLAB_class", b""))
    if cls not in NUMERIC_CLASSES:
        raise FileFormatError(f"{where}: variable {key!r} has MATLAB class {cls or '(none)'!r}; "
                              "expected a numeric matrix")
    if isinstance(obj, h5py.Group):
        if "MATLAB_sparse" not in obj.attrs or "jc" not in obj:
            raise FileFormatError(f"{where}: variable {key!r} is an HDF5 group but not a MATLAB sparse matrix "
                                  "(no MATLAB_sparse attribute or no jc)")
        nrows = int(np.asarray(obj.attrs["MATLAB_sparse"]).ravel()[0])
        jc = np.asarray(obj["jc"][()], dtype=np.int64).ravel()
        nnz = int(jc[-1]) if jc.size else 0
        if nnz == 0 and "data" not in obj:
            data, ir = np.zeros(0), np.zeros(0, dtype=np.int64)
        elif "data" in obj and "ir" in obj:
            data = _complex(obj["data"][()]).ravel()
            ir = np.asarray(obj["ir"][()], dtype=np.int64).ravel()
        else:
            raise FileFormatError(f"{where}: sparse variable {key!r} has {nnz} nonzeros but no data or ir")
        if data.size != nnz or ir.size != nnz:
            raise FileFormatError(f"{where}: sparse variable {key!r} is corrupt: jc ends at {nnz}, "
                                  f"data has {data.size} and ir {ir.size} entries")
        try:
            return sp.csc_matrix((data, ir, jc), shape=(nrows, max(jc.size - 1, 0)))
        except ValueError as exc:
            raise FileFormatError(f"{where}: sparse variable {key!r} is corrupt ({exc})") from exc
    if obj.attrs.get("MATLAB_empty", 0):
        # the dataset holds the dimensions of the empty array, in MATLAB's order
        return np.zeros(tuple(int(d) for d in np.asarray(obj[()]).ravel()))
    return np.asarray(_complex(obj[()])).T


def read_mat73(path, names):
    """The variables ``names`` that the v7.3 file ``path`` holds, and the names of all its variables.

    Returns ``(variables, found)``: a dict of scipy CSC matrices (sparse
    variables) and ndarrays (dense ones, in MATLAB's shape), and the sorted
    names of every variable in the file.

    Raises
    ------
    FileFormatError
        An HDF5 file h5py cannot open, one that is not a MATLAB file (no
        ``MATLAB_class`` attribute on any root object), or a requested variable
        that is not a numeric matrix.
    """
    import h5py

    try:
        fh = h5py.File(path, "r")
    except OSError as exc:
        raise FileFormatError(f"{path}: an HDF5 file h5py cannot open ({exc})") from exc
    with fh:
        found = sorted(k for k in fh.keys() if not k.startswith("#"))
        marked = [k for k in found if "MATLAB_class" in fh[k].attrs]
        if not marked:
            # the MATLAB_class attributes carry the layout; MATLAB's 512-byte header alone would not
            raise FileFormatError(f"{path}: an HDF5 file but not a MATLAB v7.3 file: none of its root objects "
                                  f"{found} has a MATLAB_class attribute")
        return {k: _variable(fh[k], path, k) for k in names if k in fh}, found
