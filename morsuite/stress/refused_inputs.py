r"""Builders of the bad inputs of :mod:`morsuite.stress.refused`: small models, specs, files
and reduced models, each altered in one way (no test logic; the table says what must be refused)."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import scipy.io as sio
import scipy.sparse as sp

import morsuite as ms

#: the data file of the rows with ``needs_data``
DATA_FILE = "mess_msd_ind3_g600.mat"

def _parts():
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


def _model(**replace):
    p = _parts()
    p.update(replace)
    kw = {k: p.pop(k) for k in ("band",) if k in p}
    return ms.models.Index3Model(p["M"], p["D"], p["K"], p["G"], p["F"], p["L"], **kw)


def _small():
    return ms.models.dsms(20)


def _irka(**options):
    return ms.reducers.make("irka", _small(), **options)


def _modal(fom=None, **options):
    return ms.reducers.make("modal", fom if fom is not None else _small(), **options)


_SPEC = {"name": "t", "models": {"d": "dsms:g=20"}, "methods": {"irka": {}},
         "scenes": [{"name": "s", "kind": "error", "model": "d", "r": 2}]}


def _spec(**edit):
    """A copy of a minimal valid study dict with top-level or scene keys replaced (``scene_*``)."""
    from ..studies.spec import study_from_dict

    data = copy.deepcopy(_SPEC)
    for k, v in edit.items():
        if k.startswith("scene_"):
            data["scenes"][0][k[6:]] = v
        else:
            data[k] = v
    return study_from_dict(data)


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _mat_without(tmp: Path, data: Path, key: str) -> Path:
    raw = sio.loadmat(str(data / DATA_FILE))
    kept = {k: v for k, v in raw.items() if not k.startswith("__") and k != key}
    out = tmp / f"no{key}.mat"
    sio.savemat(str(out), kept)
    return out


def _npz_without(tmp: Path, key: str) -> Path:
    out = tmp / "m.npz"
    ms.models.save_npz(_small(), out)
    with np.load(out, allow_pickle=False) as z:
        data = {k: z[k] for k in z.files if k != key}
    bad = tmp / f"no_{key}.npz"
    np.savez(bad, **data)
    return bad


def _mtx_set(tmp: Path, name: str, drop=(), sign="physical", **replace) -> Path:
    """The Matrix Market set ``tmp/name/m_KEY.mtx`` of dsms(20), without the keys in ``drop``."""
    fom = _small()
    flip = -1.0 if sign == "mess" else 1.0
    mats = {"M": fom.M, "D": flip * fom.D, "K": flip * fom.K, "G": fom.G, "B": fom.F, "C": fom.L, **replace}
    d = tmp / name
    d.mkdir(exist_ok=True)
    for key, X in mats.items():
        if key not in drop:
            sio.mmwrite(str(d / f"m_{key}.mtx"), X)
    return d


def _hdf5(tmp: Path, name: str, matlab_class=None, keys=("M",)) -> Path:
    """An HDF5 .mat file with sparse-group variables ``keys`` (MATLAB_class ``matlab_class``, if any)."""
    import h5py

    path = tmp / name
    with h5py.File(path, "w", userblock_size=512) as f:
        for key in keys:
            g = f.create_group(key)
            g.create_dataset("jc", data=np.zeros(2, dtype=np.uint64))
            if matlab_class is not None:
                g.attrs["MATLAB_class"] = np.bytes_(matlab_class)
                g.attrs["MATLAB_sparse"] = np.uint64(1)
    return path


def _pole_model():
    n1 = 4
    K = sp.diags([-1.0, 2.0, 2.0, 2.0], format="csr")
    G = sp.csr_matrix(([1.0, -1.0], ([0, 0], [1, 3])), shape=(1, n1))
    F = np.ones((n1, 1))
    return ms.models.Index3Model(sp.identity(n1), sp.csr_matrix((n1, n1)), K, G, F, F.T)


def _lradi():
    import importlib
    return importlib.import_module("morsuite.linalg.lradi").lradi


def _rom(fom=None, r=2):
    """A second-order BT reduced model of dsms(20) (or of ``fom``)."""
    return ms.reducers.make("bt", fom or _small(), form="vv").reduce(r).rom


def _changed_rom_file(tmp):
    """``STEM.npz`` written by save_rom, then one bit of it flipped (its sidecar kept): what load_rom reads."""
    from ..romfiles import load_rom, save_rom
    npz = save_rom(ms.rom.SecondOrderROM(np.eye(2), np.eye(2), np.eye(2), np.ones(2), np.ones(2)), tmp / "c")[0]
    data = bytearray(npz.read_bytes())
    data[-40] ^= 1
    npz.write_bytes(bytes(data))
    return load_rom(npz)


def _nan_rom():
    rom = _rom()
    rom.K[0, 0] = np.nan  # after construction: the ROM's own check has passed
    return rom


def _other_io_rom():
    """A reduced model with 2 inputs and 2 outputs (dsms(20) has 1 and 3)."""
    return _rom(ms.models.random_constrained(n1=20, n2=2, m=2, p=2))


def _time_spec(**scene):
    """A minimal valid study with one time scene, its keys replaced by ``scene``."""
    return _spec(scenes=[{"name": "s", "kind": "time", "model": "d", "r": 2, **scene}])


def _sim(u_edit=None, m=None):
    t = ms.analysis.signals.time_grid(10.0, 1.0)
    u = np.ones((t.size, m or 1))
    if u_edit:
        u[3, 0] = np.nan
    return ms.analysis.simulate(_small(), t, u)
