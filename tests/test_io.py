"""Model files: npz round trip, M.E.S.S. .mat loading, every bad file."""

from __future__ import annotations

import os
import zipfile

import numpy as np
import pytest
import scipy.io as sio
import scipy.sparse as sp

import morsuite as ms
from morsuite.models import load, load_mat, load_npz, save_npz


def assert_same_model(a, b):
    for key in ("M", "D", "K", "G"):
        X, Y = getattr(a, key), getattr(b, key)
        assert sp.issparse(Y) and X.shape == Y.shape and X.nnz == Y.nnz, key
        assert (X != Y).nnz == 0, key
    assert np.array_equal(a.F, b.F) and np.array_equal(a.L, b.L)
    assert a.name == b.name and a.band == b.band


@pytest.fixture
def g600(data_dir):
    return data_dir / "mess_msd_ind3_g600.mat"


@pytest.mark.parametrize("factory", [lambda: ms.models.dsms(30), lambda: ms.models.tcom(nc=6),
                                     lambda: ms.models.tcom(nc=3, constrained=False)])
def test_npz_round_trip(tmp_path, factory):
    fom = factory()
    path = save_npz(fom, tmp_path / "model.npz")
    assert path == tmp_path / "model.npz" and path.is_file()
    back = load_npz(path)
    assert_same_model(fom, back)
    assert np.array_equal(back.transfer(0.1j), fom.transfer(0.1j))
    assert_same_model(fom, load(path))


def test_npz_round_trip_of_loaded_mat(tmp_path, g600):
    fom = load_mat(g600)
    assert_same_model(fom, load_npz(save_npz(fom, tmp_path / "g600.npz")))


def test_npz_has_no_pickles(tmp_path):
    path = save_npz(ms.models.dsms(10), tmp_path / "m.npz")
    with np.load(path, allow_pickle=False) as z:
        for k in z.files:
            assert z[k].dtype != object, k


def test_save_npz_atomic_no_temp_left(tmp_path):
    fom = ms.models.dsms(10)
    save_npz(fom, tmp_path / "m.npz")
    save_npz(ms.models.dsms(12), tmp_path / "m.npz")  # overwrite
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.npz"]
    assert load_npz(tmp_path / "m.npz").n1 == 12


def test_save_npz_creates_directory(tmp_path):
    path = save_npz(ms.models.dsms(10), tmp_path / "a" / "b" / "m.npz")
    assert path.is_file()


def test_save_npz_interrupted_keeps_old_file(tmp_path, monkeypatch):
    path = save_npz(ms.models.dsms(10), tmp_path / "m.npz")
    before = path.read_bytes()

    def boom(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez_compressed", boom)
    with pytest.raises(KeyboardInterrupt):
        save_npz(ms.models.dsms(12), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.npz"]


def test_save_npz_refuses_non_model(tmp_path):
    with pytest.raises(ms.InputError, match="model must be an Index3Model"):
        save_npz({"M": 1}, tmp_path / "m.npz")


@pytest.mark.parametrize("loader", [load_npz, load_mat, load])
def test_missing_file(tmp_path, loader):
    path = tmp_path / ("nothing.npz" if loader is not load_mat else "nothing.mat")
    with pytest.raises(ms.FileFormatError, match=r"nothing\.(npz|mat).*does not exist"):
        loader(path)


def test_directory_is_not_a_file(tmp_path):
    d = tmp_path / "dir.npz"
    d.mkdir()
    with pytest.raises(ms.FileFormatError, match="not a file"):
        load_npz(d)


@pytest.mark.parametrize("content", [b"garbage bytes, not a zip" * 10, b"", b"PK\x03\x04" + b"\x00" * 50,
                                     b"\x93NUMPY\x01\x00garbage"])
def test_corrupt_npz(tmp_path, content):
    path = tmp_path / "bad.npz"
    path.write_bytes(content)
    with pytest.raises(ms.FileFormatError, match=r"bad\.npz"):
        load_npz(path)


def test_corrupt_npz_damaged_inside(tmp_path):
    """Damage in the middle of the compressed data: the zip directory is intact
    but inflating a member fails (zlib error or bad CRC)."""
    path = save_npz(ms.models.dsms(200), tmp_path / "m.npz")
    raw = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as z:
        info = z.getinfo("M_data.npy")
        size = info.compress_size
    # local header: 30 fixed bytes, then name and extra field of the lengths stored at 26 and 28
    h = info.header_offset
    start = h + 30 + int.from_bytes(raw[h + 26:h + 28], "little") + int.from_bytes(raw[h + 28:h + 30], "little")
    for off in range(start, start + size, max(1, size // 8)):
        bad = bytearray(raw)
        for i in range(off, min(off + 16, start + size)):
            bad[i] ^= 0xFF
        (tmp_path / "bad.npz").write_bytes(bytes(bad))
        with pytest.raises(ms.FileFormatError, match=r"bad\.npz"):
            load_npz(tmp_path / "bad.npz")


@pytest.mark.parametrize("corrupt", ["garbage", "empty"])
def test_corrupt_mat(tmp_path, corrupt):
    path = tmp_path / "bad.mat"
    path.write_bytes(b"MATLAB 5.0 MAT-file garbage" * 20 if corrupt == "garbage" else b"")
    with pytest.raises(ms.FileFormatError, match=r"bad\.mat"):
        load_mat(path)


def _rewrite_npz(src, dst, drop=(), change=None):
    with np.load(src, allow_pickle=False) as z:
        content = {k: z[k] for k in z.files if k not in drop}
    content.update(change or {})
    np.savez(dst, **content)


@pytest.mark.parametrize("key", ["K_data", "G_indptr", "M_shape", "F", "L"])
def test_npz_missing_key(tmp_path, key):
    src = save_npz(ms.models.dsms(10), tmp_path / "good.npz")
    dst = tmp_path / "lacking.npz"
    _rewrite_npz(src, dst, drop=(key,))
    with pytest.raises(ms.FileFormatError, match=rf"lacking\.npz.*missing key {key}\b"):
        load_npz(dst)


def test_npz_wrong_format_tag(tmp_path):
    src = save_npz(ms.models.dsms(10), tmp_path / "good.npz")
    _rewrite_npz(src, tmp_path / "other.npz", change={"format": np.array("something-else")})
    with pytest.raises(ms.FileFormatError, match=r"other\.npz.*'format'"):
        load_npz(tmp_path / "other.npz")
    _rewrite_npz(src, tmp_path / "none.npz", drop=("format",))
    with pytest.raises(ms.FileFormatError, match=r"none\.npz.*'format'"):
        load_npz(tmp_path / "none.npz")


def test_npz_inconsistent_matrix(tmp_path):
    src = save_npz(ms.models.dsms(10), tmp_path / "good.npz")
    _rewrite_npz(src, tmp_path / "bad.npz", change={"K_indptr": np.array([0, 1, 2], dtype=np.int32)})
    with pytest.raises(ms.FileFormatError, match=r"bad\.npz.*matrix K"):
        load_npz(tmp_path / "bad.npz")


def test_npz_with_pickled_entry_refused(tmp_path):
    src = save_npz(ms.models.dsms(10), tmp_path / "good.npz")
    _rewrite_npz(src, tmp_path / "pickled.npz", change={"F": np.array([{"a": 1}], dtype=object)})
    with pytest.raises(ms.FileFormatError, match=r"pickled\.npz"):
        load_npz(tmp_path / "pickled.npz")


def test_npz_content_still_validated(tmp_path):
    """A well-formed file with bad numbers is refused by Index3Model."""
    src = save_npz(ms.models.dsms(10), tmp_path / "good.npz")
    with np.load(src) as z:
        data = z["K_data"].copy()
    data[0] = np.nan
    _rewrite_npz(src, tmp_path / "nan.npz", change={"K_data": data})
    with pytest.raises(ms.InputError, match="matrix K has non-finite"):
        load_npz(tmp_path / "nan.npz")


def test_mat_lacking_G(tmp_path, g600):
    raw = sio.loadmat(str(g600))
    content = {k: v for k, v in raw.items() if not k.startswith("__") and k != "G"}
    sio.savemat(str(tmp_path / "noG.mat"), content)
    with pytest.raises(ms.FileFormatError, match=r"noG\.mat.*missing matrix G"):
        load_mat(tmp_path / "noG.mat")


def test_mat_lacking_B(tmp_path, g600):
    raw = sio.loadmat(str(g600))
    content = {k: v for k, v in raw.items() if not k.startswith("__") and k != "B"}
    sio.savemat(str(tmp_path / "noB.mat"), content)
    with pytest.raises(ms.FileFormatError, match=r"noB\.mat.*missing matrix B"):
        load_mat(tmp_path / "noB.mat")


def test_mat_with_F_and_L(tmp_path):
    fom = ms.models.dsms(20)
    sio.savemat(str(tmp_path / "fl.mat"), {"M": fom.M, "D": -fom.D, "K": -fom.K, "G": fom.G,
                                           "F": fom.F, "L": fom.L})
    assert_same_model(fom, load_mat(tmp_path / "fl.mat", name=fom.name))
    sio.savemat(str(tmp_path / "phys.mat"), {"M": fom.M, "D": fom.D, "K": fom.K, "G": fom.G,
                                             "F": fom.F, "L": fom.L})
    assert_same_model(fom, load_mat(tmp_path / "phys.mat", sign="physical", name=fom.name))


def test_mat_wrong_sign_convention_detected(g600):
    """The M.E.S.S. file read as physical would give negated D and K: the stored
    realization contradicts that and the loader says so."""
    with pytest.raises(ms.FileFormatError, match=r"sign"):
        load_mat(g600, sign="physical")


def test_mat_physical_file_read_as_mess_detected(tmp_path):
    fom = ms.models.dsms(20)
    E, A, B, C = fom.first_order()
    sio.savemat(str(tmp_path / "phys.mat"), {"M": fom.M, "D": fom.D, "K": fom.K, "G": fom.G,
                                             "E": E, "A": A, "B": B, "C": C})
    with pytest.raises(ms.FileFormatError, match=r"sign"):
        load_mat(tmp_path / "phys.mat")
    assert_same_model(fom, load_mat(tmp_path / "phys.mat", sign="physical", name=fom.name))


def test_mat_bad_sign_argument(g600):
    with pytest.raises(ms.InputError, match="sign must be"):
        load_mat(g600, sign="negative")


@pytest.mark.parametrize("name", ["model.txt", "model", "model.npz.bak", "model.MAT5"])
def test_unknown_extension(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(b"x")
    with pytest.raises(ms.FileFormatError, match=r"unknown extension"):
        load(path)


def test_load_by_extension(g600):
    fom = load(g600)
    assert fom.n1 == 600 and fom.name == "mess_msd_ind3_g600"


def test_saved_file_permissions_follow_umask(tmp_path):
    """An atomically written file must be as readable as a plainly written one."""
    plain = tmp_path / "plain"
    plain.write_bytes(b"")
    path = save_npz(ms.models.dsms(10), tmp_path / "m.npz")
    assert (os.stat(path).st_mode & 0o777) == (os.stat(plain).st_mode & 0o777)


# ---------------------------------------------------------------------------
# benchmark result files (morsuite.bench): plain JSON, written atomically
# ---------------------------------------------------------------------------

def test_bench_run_writes_json_and_manifest(tmp_path, monkeypatch, capsys):
    import json

    from morsuite import bench

    def toy(quick):
        return {"n": 3, "array": np.arange(3), "ratios": {"toy_ratio": {"value": 1.1, "target": 1.3},
                                                          "slow": {"value": 2.0, "target": 1.3}}}

    monkeypatch.setitem(bench.BENCHMARKS, "toy", toy)
    res = bench.run(["toy"], out_dir=tmp_path / "b", quick=True)
    out = capsys.readouterr().out.splitlines()
    assert out == ["toy: toy_ratio = 1.100 (target <= 1.3) ok",
                   "toy: slow = 2.000 (target <= 1.3) ABOVE TARGET"]
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == ["manifest.json", "toy.json"]
    data = json.loads((tmp_path / "b" / "toy.json").read_text())
    assert data["array"] == [0, 1, 2] and data["quick"] is True
    assert data["ratios"]["toy_ratio"]["pass"] is True and data["ratios"]["slow"]["pass"] is False
    assert res["toy"]["n"] == 3
    manifest = json.loads((tmp_path / "b" / "manifest.json").read_text())
    assert manifest["machine"]["cpu_count"] == os.cpu_count()
    assert "numpy" in manifest["machine"]["versions"] and "threads_env" in manifest["machine"]
    assert manifest["benchmarks"]["toy"]["file"] == "toy.json"


def test_bench_unknown_name(tmp_path):
    from morsuite import bench

    with pytest.raises(ms.OptionError, match=r"unknown benchmark 'nope'.*freqresp"):
        bench.run(["nope"], out_dir=tmp_path)
    assert not any(tmp_path.iterdir())


def test_bench_registry_and_cli_list(capsys):
    from morsuite import bench
    from morsuite.cli import main

    assert "freqresp" in bench.BENCHMARKS
    with pytest.raises(ms.OptionError, match="already registered"):
        bench.benchmark("freqresp")(lambda quick: {})
    assert main(["bench", "--list"]) == 0
    assert "freqresp" in [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert main(["bench", "nope"]) == 2
