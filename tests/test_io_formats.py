"""MATLAB v7.3 (HDF5) files and Matrix Market sets, against the v5 .mat loader.

The v7.3 files are written here with h5py in the layout MATLAB uses (512-byte
header, sparse matrices as groups with MATLAB_sparse, data, ir, jc; dense arrays
transposed; gzip-compressed chunks as MATLAB's default -v7.3 writes them); the
Matrix Market sets with scipy.io.mmwrite under the names the collections use.
The reference for the transfer function is the file's own first-order
realization C (sE - A)^-1 B, solved densely.
"""

from __future__ import annotations

import gzip

import h5py
import numpy as np
import pytest
import scipy.io as sio
import scipy.sparse as sp

import morsuite as ms
from morsuite.modelfiles import is_model_path, matrix_market_set, model_files, split_member
from morsuite.models import load, load_mat, load_mtx
from morsuite.models.mat73 import is_hdf5, read_mat73

POINTS = (0.01j, 0.16j, 1j, 0.3 + 0.5j)


@pytest.fixture(scope="module")
def raw(data_dir):
    return {k: v for k, v in sio.loadmat(str(data_dir / "mess_msd_ind3_g600.mat")).items()
            if not k.startswith("__")}


@pytest.fixture(scope="module")
def ref(data_dir):
    return load_mat(data_dir / "mess_msd_ind3_g600.mat")


@pytest.fixture(scope="module")
def realization(raw):
    """C (sE - A)^-1 B at POINTS from the file's first-order matrices, dense."""
    E, A, B, C = (sp.csc_matrix(raw[k]).toarray() for k in "EABC")
    return [C @ np.linalg.solve(s * E - A, B) for s in POINTS]


def write_mat73(path, variables, dense=()):
    """A MATLAB v7.3 file: the names in ``dense`` as dense datasets, the others as sparse groups."""
    with h5py.File(path, "w", userblock_size=512) as f:
        for key, value in variables.items():
            if key in dense:
                X = value.toarray() if sp.issparse(value) else np.asarray(value)
                # MATLAB stores column-major, HDF5 row-major: the dataset is the transpose
                ds = f.create_dataset(key, data=np.ascontiguousarray(X.T), compression="gzip", chunks=True)
                ds.attrs["MATLAB_class"] = np.bytes_("double")
                continue
            X = sp.csc_matrix(value)
            X.sort_indices()
            g = f.create_group(key)
            g.attrs["MATLAB_class"] = np.bytes_("double")
            g.attrs["MATLAB_sparse"] = np.uint64(X.shape[0])
            if X.nnz:  # MATLAB writes no data and ir for an all-zero sparse matrix
                g.create_dataset("data", data=X.data, compression="gzip", chunks=True)
                g.create_dataset("ir", data=X.indices.astype(np.uint64), compression="gzip", chunks=True)
            g.create_dataset("jc", data=X.indptr.astype(np.uint64), compression="gzip", chunks=True)
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    header = header.ljust(116, b" ") + b"\0" * 8 + b"\x00\x02" + b"IM"
    with open(path, "r+b") as fh:
        fh.write(header.ljust(512, b"\0"))
    return path


def assert_same(a, b, realization=None):
    for key in "MDKG":
        X, Y = getattr(a, key), getattr(b, key)
        assert X.shape == Y.shape and X.nnz == Y.nnz and (X != Y).nnz == 0, key
    assert np.array_equal(a.F, b.F) and np.array_equal(a.L, b.L)
    for i, s in enumerate(POINTS):
        Ta, Tb = a.transfer(s), b.transfer(s)
        assert np.linalg.norm(Ta - Tb) <= 1e-13 * np.linalg.norm(Ta)  # equal matrices (above): the same solves
        if realization is not None:
            assert np.linalg.norm(Tb - realization[i]) <= 1e-11 * np.linalg.norm(realization[i])


# ---------------------------------------------------------------------------
# MATLAB v7.3
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("dense", [(), ("B", "C", "G", "M")], ids=["all-sparse", "dense-B-C-G-M"])
def test_mat73_equals_v5_loader(tmp_path, raw, ref, realization, dense):
    path = write_mat73(tmp_path / "g600.mat", raw, dense=dense)
    assert is_hdf5(path)
    with pytest.raises(NotImplementedError):  # what scipy alone does with it
        sio.loadmat(str(path))
    fom = load(path)
    assert fom.name == "g600" and (fom.n1, fom.n2, fom.m, fom.p) == (600, 1, 1, 3)
    assert_same(ref, fom, realization)


def test_mat73_reads_only_the_model_variables(tmp_path, raw):
    path = write_mat73(tmp_path / "g600.mat", raw, dense=("C",))
    variables, found = read_mat73(path, ("G", "C", "Q"))
    assert found == sorted(raw)
    assert sorted(variables) == ["C", "G"]
    assert isinstance(variables["C"], np.ndarray) and variables["C"].shape == (3, 1201)
    assert sp.issparse(variables["G"]) and variables["G"].shape == (1, 600)


def test_mat73_empty_and_all_zero_sparse(tmp_path):
    path = tmp_path / "e.mat"
    write_mat73(path, {"Z": sp.csc_matrix((4, 3)), "A": np.arange(6.0).reshape(2, 3)}, dense=("A",))
    with h5py.File(path, "a") as f:
        ds = f.create_dataset("E", data=np.array([0, 5], dtype=np.uint64))
        ds.attrs["MATLAB_class"] = np.bytes_("double")
        ds.attrs["MATLAB_empty"] = np.uint8(1)
    v, _ = read_mat73(path, ("Z", "A", "E"))
    assert v["Z"].shape == (4, 3) and v["Z"].nnz == 0
    assert np.array_equal(v["A"], np.arange(6.0).reshape(2, 3))
    assert v["E"].shape == (0, 5)


@pytest.mark.parametrize("key, change, message", [
    ("C", lambda C: C + sp.csr_matrix(([1.0], ([0], [700])), shape=C.shape),
     r"C has nonzeros outside its first n1 = 600 columns \(velocity outputs\)"),
    ("B", lambda B: B + sp.csr_matrix(([1.0], ([3], [0])), shape=B.shape),
     r"B has nonzeros outside its velocity block \(rows n1 = 600 to 2 n1 = 1200\)"),
    ("B", lambda B: B[:900], r"B has 900 rows; expected n1 = 600 \(second-order F\) or at least 2 n1 = 1200")])
@pytest.mark.parametrize("version", ["v5", "v7.3"])
def test_mat_first_order_blocks_checked(tmp_path, raw, key, change, message, version):
    """A velocity output or a force on a position would be silently dropped by taking blocks."""
    content = {**raw, key: change(sp.csr_matrix(raw[key]))}
    path = tmp_path / "bad.mat"
    if version == "v5":
        sio.savemat(str(path), content)
    else:
        write_mat73(path, content)
    with pytest.raises(ms.FileFormatError, match=rf"bad\.mat: {message}"):
        load_mat(path)


def test_mat73_wrong_sign_detected(tmp_path, raw):
    path = write_mat73(tmp_path / "g600.mat", raw)
    with pytest.raises(ms.FileFormatError, match=r"does not follow the sign='physical' convention"):
        load_mat(path, sign="physical")


def test_mat73_missing_variable(tmp_path, raw):
    path = write_mat73(tmp_path / "noG.mat", {k: v for k, v in raw.items() if k != "G"})
    with pytest.raises(ms.FileFormatError, match=r"noG\.mat: missing matrix G \(found \['A', 'B', 'C', 'D'"):
        load_mat(path)


def test_hdf5_file_not_from_matlab(tmp_path):
    path = tmp_path / "plain.mat"
    with h5py.File(path, "w") as f:
        f.create_dataset("M", data=np.eye(3))
        f.create_group("results").create_dataset("x", data=np.ones(2))
    with pytest.raises(ms.FileFormatError, match=r"plain\.mat: an HDF5 file but not a MATLAB v7\.3 file.*"
                                                  r"\['M', 'results'\]"):
        load(path)


def test_mat73_header_without_hdf5_body(tmp_path, raw):
    good = write_mat73(tmp_path / "good.mat", {"M": raw["M"]}).read_bytes()
    (tmp_path / "cut.mat").write_bytes(good[:512] + b"\0" * 600)
    with pytest.raises(ms.FileFormatError, match=r"cut\.mat: says MATLAB v7\.3 \(HDF5\) but holds no HDF5 data"):
        load_mat(tmp_path / "cut.mat")
    (tmp_path / "trunc.mat").write_bytes(good[:700])
    with pytest.raises(ms.FileFormatError, match=r"trunc\.mat: an HDF5 file h5py cannot open"):
        load_mat(tmp_path / "trunc.mat")


def test_mat73_variable_of_another_class(tmp_path, raw):
    path = write_mat73(tmp_path / "s.mat", raw)
    with h5py.File(path, "a") as f:
        del f["K"]
        g = f.create_group("K")
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        g.create_dataset("a", data=np.ones(1))
    with pytest.raises(ms.FileFormatError, match=r"variable 'K' has MATLAB class 'struct'; expected a numeric"):
        load_mat(path)


def test_mat73_corrupt_sparse(tmp_path, raw):
    path = write_mat73(tmp_path / "c.mat", raw)
    with h5py.File(path, "a") as f:
        data = f["K"]["data"][()]
        del f["K"]["data"]
        f["K"].create_dataset("data", data=data[:-3])
    with pytest.raises(ms.FileFormatError, match=r"sparse variable 'K' is corrupt: jc ends at 1798, data has 1795"):
        load_mat(path)


# ---------------------------------------------------------------------------
# Matrix Market sets
# ---------------------------------------------------------------------------

def write_set(directory, pattern, matrices):
    """One Matrix Market file per matrix, named ``pattern.format(KEY)``; ``.gz`` names are compressed."""
    directory.mkdir(parents=True, exist_ok=True)
    for key, X in matrices.items():
        target = directory / pattern.format(key)
        with (gzip.open(target, "wb") if target.name.endswith(".gz") else open(target, "wb")) as fh:
            sio.mmwrite(fh, X)  # a handle: mmwrite would append .mtx to a name like gyro.M
    return directory


def physical(ref, io=("B", "C")):
    return {"M": ref.M, "D": ref.D, "K": ref.K, "G": ref.G, io[0]: ref.F, io[1]: ref.L}


@pytest.mark.parametrize("pattern, name", [("{}.mtx", None), ("g600_{}.mtx", "g600"), ("g600.{}", "g600"),
                                           ("g600.{}.mtx", "g600"), ("g600-{}.mtx.gz", "g600")])
def test_mtx_set_equals_mat_loader(tmp_path, ref, realization, pattern, name):
    d = write_set(tmp_path / "set", pattern, physical(ref))
    first = next(iter(d.iterdir()))
    for path in ([d, d / name, first] if name else [d, first]):
        fom = load(path)
        assert fom.name == (name or "set")
        assert_same(ref, fom, realization)


def test_mtx_first_order_B_C_and_F_L_names(tmp_path, raw, ref, realization):
    """The first-order B, C of the .mat file give the same F, L; F and L are accepted under their own names."""
    mats = {"M": ref.M, "D": ref.D, "K": ref.K, "G": ref.G, "B": raw["B"], "C": raw["C"]}
    assert_same(ref, load_mtx(write_set(tmp_path / "fo", "m_{}.mtx", mats)), realization)
    assert_same(ref, load_mtx(write_set(tmp_path / "fl", "m_{}.mtx", physical(ref, ("F", "L")))), realization)


def test_mtx_mess_sign(tmp_path, raw, ref, realization):
    mats = {k: raw[k] for k in ("M", "D", "K", "G", "B", "C")}  # D and K as M.E.S.S. stores them
    d = write_set(tmp_path / "mess", "g.{}", mats)
    assert_same(ref, load_mtx(d / "g", sign="mess"), realization)
    with pytest.raises(ms.FileFormatError, match=r"no positive diagonal entry.*try sign='mess'"):
        load_mtx(d / "g")
    assert load_mtx(d / "g", check_sign=False).K.diagonal().max() < 0


def test_mtx_names_option(tmp_path, ref):
    d = write_set(tmp_path / "gyro", "gyro.{}", {"M": ref.M, "E": ref.D, "K": ref.K, "G": ref.G,
                                                 "B": ref.F, "C": ref.L})
    with pytest.raises(ms.FileFormatError, match=r"no file for matrix D \(looked for key D; found gyro\.B, gyro\.C, "
                                                 r"gyro\.E, gyro\.G, gyro\.K, gyro\.M\); names=\{'D': 'KEY'\}.*"
                                                 r"names=\{'D': None\} for zero damping"):
        load_mtx(d)
    assert (load_mtx(d, names={"D": "E"}).D != ref.D).nnz == 0
    undamped = load_mtx(d, names={"D": None})
    assert undamped.D.nnz == 0 and undamped.D.shape == (600, 600)
    with pytest.raises(ms.InputError, match=r"names: unknown matrix 'Q'; valid: M, D, K, G, F, L"):
        load_mtx(d, names={"Q": "E"})
    with pytest.raises(ms.InputError, match=r"names: matrix K cannot be absent"):
        load_mtx(d, names={"K": None})
    with pytest.raises(ms.FileFormatError, match=r"gyro\.C would be both matrix D and L"):
        load_mtx(d, names={"D": "C"})


def test_mtx_missing_constraints_need_saying(tmp_path, ref):
    d = write_set(tmp_path / "free", "{}.mtx", {"M": ref.M, "D": ref.D, "K": ref.K, "B": ref.F, "C": ref.L})
    with pytest.raises(ms.FileFormatError, match=r"no file for matrix G.*names=\{'G': None\} for no constraints"):
        load_mtx(d)
    assert load_mtx(d, names={"G": None}).n2 == 0


def test_mtx_ambiguous_sets(tmp_path, ref):
    mats = physical(ref)
    d = write_set(tmp_path / "two", "a_{}.mtx", mats)
    write_set(d, "b_{}.mtx", mats)
    with pytest.raises(ms.FileFormatError, match=r"holds several Matrix Market sets \(stems 'a', 'b'\)"):
        load(d)
    assert load(d / "b").name == "b"
    write_set(d, "a.{}", {"K": ref.K})
    with pytest.raises(ms.FileFormatError, match=r"both 'a\.K' and 'a_K\.mtx' would be matrix K"):
        load(d / "a")
    both = write_set(tmp_path / "fb", "{}.mtx", {**mats, "F": ref.F})
    with pytest.raises(ms.FileFormatError, match=r"both F\.mtx and B\.mtx could be matrix F"):
        load(both)


def test_mtx_bad_files(tmp_path, ref):
    d = write_set(tmp_path / "bad", "m_{}.mtx", physical(ref))
    (d / "m_K.mtx").write_text("%%MatrixMarket matrix coordinate real general\n600 600 2\n1 1 1\n")
    with pytest.raises(ms.FileFormatError, match=r"m_K\.mtx: not a readable Matrix Market file"):
        load(d)
    (d / "m_K.mtx").write_text("not a matrix\n")
    with pytest.raises(ms.FileFormatError, match=r"m_K\.mtx: not a readable Matrix Market file"):
        load(d / "m")
    with pytest.raises(ms.FileFormatError, match=r"'.*nothing' does not exist, and no Matrix Market set has that"):
        load(d / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ms.FileFormatError, match=r"holds no Matrix Market set"):
        load(tmp_path / "empty")
    (tmp_path / "x_Q.mtx").write_text("x")
    with pytest.raises(ms.FileFormatError, match=r"is not named as a member of a Matrix Market set"):
        load_mtx(tmp_path / "x_Q.mtx")


def test_mtx_shape_errors_come_from_the_model(tmp_path, ref):
    d = write_set(tmp_path / "s", "{}.mtx", {**physical(ref), "C": ref.L[:, :-1]})
    with pytest.raises(ms.FileFormatError, match=r"C\.mtx: C has 599 columns; expected n1 = 600"):
        load(d)
    d = write_set(tmp_path / "t", "{}.mtx", {**physical(ref), "K": ref.K[:-1, :-1]})
    with pytest.raises(ms.ShapeError, match=r"matrix K has shape \(599, 599\); expected \(600, 600\)"):
        load(d)


# ---------------------------------------------------------------------------
# names, the catalog and study specs
# ---------------------------------------------------------------------------

@pytest.mark.parametrize("filename, expected", [
    ("gyro.M", ("gyro", "M")), ("gyro.m", None), ("beam_m.mtx", ("beam", "M")), ("M.mtx", ("", "M")),
    ("rail_1357_c60.C", ("rail_1357_c60", "C")), ("a-b.K.mtx.gz", ("a-b", "K")), ("gyro.mtx", None),
    ("notes.txt", None), ("K", None), ("x.Mtx", None), ("x_K.MTX", ("x", "K"))])
def test_split_member(filename, expected):
    assert split_member(filename) == expected


@pytest.mark.parametrize("spec, expected", [
    ("dsms:g=600", False), ("tcom", False), ("m.mat", True), ("m.npz", True), ("data/gyro", True),
    ("./gyro", True), ("K.mtx", True), ("~/models/x", True), ("", False)])
def test_is_model_path(spec, expected):
    assert is_model_path(spec) is expected


def test_catalog_and_model_files(tmp_path, ref):
    d = write_set(tmp_path / "cat", "beam_{}.mtx", physical(ref))
    assert ms.models.parse(str(d / "beam")).n1 == 600
    assert ms.models.parse(str(d)).name == "beam"
    assert [f.name for f in model_files(d)] == sorted(f"beam_{k}.mtx" for k in "BCDGKM")
    assert matrix_market_set(d / "beam_K.mtx")[1] == "beam"


def test_study_spec_with_mtx_model(tmp_path, ref):
    from morsuite.studies import study_from_dict

    d = write_set(tmp_path / "spec", "beam_{}.mtx", physical(ref))

    def entry():
        study = study_from_dict({"name": "t", "models": {"b": str(d / "beam")}, "methods": {"irka": {}},
                                 "scenes": [{"name": "s", "kind": "error", "model": "b", "r": 2}]})
        return study.models["b"]

    first = entry()
    assert (first.n1, first.n2, first.name) == (600, 1, "beam") and first.model_id.startswith("file:beam:")
    assert entry().model_id == first.model_id
    write_set(d, "beam_{}.mtx", {"D": 2 * ref.D})
    assert entry().model_id != first.model_id
    with pytest.raises(ms.SpecError, match=r"models\.b: model file .*nope' does not exist"):
        study_from_dict({"name": "t", "models": {"b": str(d / "nope")}, "methods": {"irka": {}},
                         "scenes": [{"name": "s", "kind": "error", "model": "b", "r": 2}]})


def test_study_runs_on_mtx_model(tmp_path):
    """End to end: a study whose model is a Matrix Market set; the manifest stays JSON after mmread
    (scipy's reader registers a threadpool whose version is a function)."""
    import json

    from morsuite.studies import run

    fom = ms.models.dsms(20)
    write_set(tmp_path / "m", "d20.{}", {"M": fom.M, "D": fom.D, "K": fom.K, "G": fom.G, "B": fom.F, "C": fom.L})
    spec = tmp_path / "s.toml"
    spec.write_text('name = "s"\n[models]\nd = "m/d20"\n[methods.irka]\n'
                    '[[scenes]]\nname = "t"\nkind = "table"\nmodel = "d"\nr = 4\n')
    res = run(spec, out=tmp_path / "out", quiet=True, formats=())
    manifest = json.loads((tmp_path / "out" / "s" / "manifest.json").read_text())
    assert manifest["models"]["d"]["model_id"].startswith("file:d20:")
    row = res.summary.iloc[0]
    rom = ms.reducers.make("irka", fom).reduce(4).rom
    omega = np.logspace(-2, 0, 200)
    direct = ms.analysis.errors(fom, rom, omega)["abs_error"].max()
    assert row["model"] == "d20" and abs(row["max_abs_error"] - direct) <= 1e-8 * direct
