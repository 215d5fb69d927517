"""Reduced models as files (morsuite.romfiles), `morsuite reduce --save`, `morsuite verify` and `to_control`.

References: the bytes of the arrays written (round trips), scipy.io.loadmat and Octave (the .mat
file), the transfer function of a first-order realization built from the documented variables
(dense numpy), SHA-256 of the files (hashlib), python-control's evaluation of `to_control()`.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import subprocess
import warnings

import numpy as np
import pytest
import scipy.io as sio
import scipy.sparse as sp

import morsuite as ms
from morsuite import cli
from morsuite.romfiles import (ERROR_KEYS, VARIABLES, grid_omega, load_rom, model_hash, provenance_of,
                               read_sidecar, save_rom)
from support import assert_rounding, transfer_tolerance


@pytest.fixture(scope="module")
def dsms():
    return ms.models.dsms(g=50)


@pytest.fixture(scope="module")
def mimo():
    return ms.models.random_constrained(n1=30, n2=2, m=2, p=3, seed=1)


@pytest.fixture(scope="module")
def reductions(dsms, mimo):
    """(model, method, Reduction) for real reductions: both ROM kinds, SISO/SIMO and MIMO."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # recorded in info["warnings"]
        return [(fom, method, ms.reducers.make(method, fom).reduce(r))
                for fom, method, r in ((dsms, "bt", 6), (dsms, "irka", 4), (mimo, "bt", 6), (mimo, "irka", 4))]


def _same_bits(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_round_trip_is_bit_identical_through_npz_and_mat(tmp_path, reductions):
    for k, (fom, method, res) in enumerate(reductions):
        rom = res.rom
        prov = provenance_of(fom, method, {}, res.info)
        written = save_rom(rom, tmp_path / f"rom{k}.npz", provenance=prov)
        assert [p.name for p in written] == [f"rom{k}.npz", f"rom{k}.mat", f"rom{k}.json"]
        for path in (written[0], written[1], tmp_path / f"rom{k}", written[2]):  # each file, the stem, the sidecar
            back = load_rom(path)
            assert type(back) is type(rom) and back.kind == rom.kind
            for name in VARIABLES[rom.kind]:
                assert _same_bits(getattr(back, name), getattr(rom, name)), (method, path, name)
            assert back.provenance["provenance"] == json.loads(json.dumps(prov))
        # the sidecar's hashes are the files' SHA-256
        side = read_sidecar(written[2])
        for fmt, path in zip(("npz", "mat"), written):
            assert side["files"][fmt]["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
        assert (side["kind"], side["order"], side["states"], side["m"], side["p"]) == \
            (rom.kind, rom.order, rom.states, rom.m, rom.p)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary file left
    assert ms.load_rom is load_rom and ms.rom.load_rom(written[1]).order == rom.order


def test_loadmat_reads_the_documented_variables(tmp_path, reductions):
    """The .mat file holds `kind` and the documented matrices; the first-order realization the module
    docstring tells MATLAB/Octave users to build has the reduced model's transfer function."""
    for k, (_, _, res) in enumerate(reductions):
        rom = res.rom
        save_rom(rom, tmp_path / f"r{k}", formats=("mat",))
        raw = sio.loadmat(str(tmp_path / f"r{k}.mat"))
        names = {n for n in raw if not n.startswith("__")}
        assert names == {"kind", *VARIABLES[rom.kind]}
        assert raw["kind"].dtype.kind == "U" and raw["kind"].shape == (1,) and raw["kind"][0] == rom.kind
        v = {n: raw[n] for n in VARIABLES[rom.kind]}
        assert all(x.dtype == np.float64 for x in v.values())
        s = 0.3 + 0.9j
        if rom.kind == "second-order":
            r, m, p = v["M"].shape[0], v["F"].shape[1], v["L"].shape[0]
            assert (v["K"].shape, v["F"].shape, v["L"].shape) == ((r, r), (r, m), (p, r))
            E = np.block([[np.eye(r), np.zeros((r, r))], [np.zeros((r, r)), v["M"]]])
            A = np.block([[np.zeros((r, r)), np.eye(r)], [-v["K"], -v["D"]]])
            B, C, D = np.vstack([np.zeros((r, m)), v["F"]]), np.hstack([v["L"], np.zeros((p, r))]), np.zeros((p, m))
        else:
            E, A, B, C, D = (v[n] for n in ("E", "A", "B", "C", "D"))
            assert D.shape == (C.shape[0], B.shape[1])
        P = s * E - A
        H = C @ np.linalg.solve(P, B) + D
        ref = rom.transfer(s)
        tol = transfer_tolerance(P, B, C, factor=2.0)  # two solves, two realizations
        assert_rounding(np.linalg.norm(H - ref) / np.linalg.norm(ref), tol, f"documented realization, {rom.kind}")


@pytest.mark.skipif(shutil.which("octave") is None, reason="Octave is not installed")
def test_octave_loads_the_mat_file(tmp_path, reductions):
    """Octave reads the .mat file; the matrices it sees give the reduced model's response (computed in Octave)."""
    _, _, res = reductions[3]  # MIMO second-order
    rom = res.rom
    save_rom(rom, tmp_path / "so")
    script = ("load('so.mat'); s = 0.3 + 0.9i; H = L * ((s^2*M + s*D + K) \\ F); "
              "printf('%s %d %d %d\\n', kind, size(M, 1), size(F, 2), size(L, 1)); "
              "printf('%.17g %.17g\\n', [real(H(:)) imag(H(:))]');")
    out = subprocess.run(["octave", "--no-gui", "--quiet", "--eval", script], cwd=tmp_path, capture_output=True,
                         text=True, timeout=120).stdout.split("\n")
    assert out[0].split() == ["second-order", str(rom.order), str(rom.m), str(rom.p)]
    H = np.array([complex(float(a), float(b)) for a, b in (line.split() for line in out[1:] if line.strip())])
    ref = rom.transfer(0.3 + 0.9j).ravel(order="F")
    P = (0.3 + 0.9j) ** 2 * rom.M + (0.3 + 0.9j) * rom.D + rom.K
    assert_rounding(np.linalg.norm(H - ref) / np.linalg.norm(ref), transfer_tolerance(P, rom.F, rom.L, factor=2.0),
                    "Octave's response")


def test_sidecar_hash_detects_a_changed_file_and_bad_files_are_refused(tmp_path, reductions):
    rom = reductions[1][2].rom
    npz, mat, side = save_rom(rom, tmp_path / "a")
    for path in (npz, mat):
        data = bytearray(path.read_bytes())
        data[len(data) // 2] ^= 0x01  # one bit
        path.write_bytes(bytes(data))
        with pytest.raises(ms.FileFormatError, match=re.escape(str(path)) + r".*SHA-256 .* differs"):
            load_rom(path)
    # without a sidecar a file is read as it is, with no provenance
    side.unlink()
    rom.save(mat)
    assert load_rom(mat).provenance is None and _same_bits(load_rom(mat).K, rom.K)
    # a sidecar that does not list the file; one that is not a sidecar; truncated and unknown files
    save_rom(rom, tmp_path / "c", formats=("npz",))
    rom.save(tmp_path / "c.mat")
    with pytest.raises(ms.FileFormatError, match=r"c\.json.* does not list it"):
        load_rom(tmp_path / "c.mat")
    (tmp_path / "d.json").write_text("{not json")
    rom.save(tmp_path / "d.npz")
    with pytest.raises(ms.FileFormatError, match=r"sidecar .*d\.json.* is not readable JSON"):
        load_rom(tmp_path / "d.npz")
    with pytest.raises(ms.InputError, match=r"d\.json exists and is not a morsuite ROM sidecar"):
        save_rom(rom, tmp_path / "d")
    (tmp_path / "e.npz").write_bytes(npz.read_bytes()[:100])
    with pytest.raises(ms.FileFormatError, match=r"e\.npz.* is not a readable NumPy \.npz archive"):
        load_rom(tmp_path / "e.npz")
    np.savez(tmp_path / "f.npz", kind=np.array("third-order"), M=np.eye(2))
    with pytest.raises(ms.FileFormatError, match=r"f\.npz.*'kind' missing or unknown \('third-order'\)"):
        load_rom(tmp_path / "f.npz")
    sio.savemat(tmp_path / "g.mat", {"kind": "second-order", "M": np.eye(2), "D": np.eye(2), "K": np.eye(3),
                                      "F": np.ones((2, 1)), "L": np.ones((1, 2))})
    with pytest.raises(ms.FileFormatError, match=r"g\.mat.*matrix K has shape \(3, 3\)"):
        load_rom(tmp_path / "g.mat")
    with pytest.raises(ms.FileFormatError, match=r"neither .*h\.npz nor .*h\.mat exists"):
        load_rom(tmp_path / "h")
    with pytest.raises(ms.InputError, match="formats must be distinct names out of npz, mat"):
        save_rom(rom, tmp_path / "i", formats=("npz", "txt"))
    with pytest.raises(ms.InputError, match="rom must be a SecondOrderROM or FirstOrderROM"):
        save_rom(np.eye(2), tmp_path / "j")


def _rebuilt(fom, how):
    """The same matrices stored otherwise: CSC, explicit zeros and split duplicates, int64 indices."""
    def store(X):
        X = sp.csr_matrix(X)
        if how == "csc":
            return sp.csc_matrix(X)
        coo = X.tocoo()
        if how == "coo":  # every entry split into two halves, plus an explicit zero
            rows = np.concatenate([coo.row, coo.row, [0]])
            cols = np.concatenate([coo.col, coo.col, [X.shape[1] - 1]])
            data = np.concatenate([coo.data / 2, coo.data - coo.data / 2, [0.0]])
            return sp.coo_matrix((data, (rows, cols)), shape=X.shape)
        Y = sp.csr_matrix(X)
        Y.indptr, Y.indices = Y.indptr.astype(np.int64), Y.indices.astype(np.int64)
        return Y
    return ms.models.Index3Model(*(store(getattr(fom, k)) for k in ("M", "D", "K", "G")), fom.F.copy(),
                                 fom.L.copy(), name="another name", band=(1e-3, 2.0), check_constraints=False)


def test_model_hash_is_content_identity(mimo):
    h = model_hash(mimo)
    assert re.fullmatch(r"[0-9a-f]{64}", h)
    for how in ("csc", "coo", "int64"):
        assert model_hash(_rebuilt(mimo, how)) == h, how
    K = sp.csr_matrix(mimo.K, copy=True)
    K.data[0] = np.nextafter(K.data[0], np.inf)  # one entry one unit in the last place up
    other = ms.models.Index3Model(mimo.M, mimo.D, K, mimo.G, mimo.F, mimo.L, check_constraints=False)
    assert model_hash(other) != h
    assert model_hash(mimo.with_io(L=mimo.L[:2])) != h
    with pytest.raises(ms.InputError, match="fom must be a model with matrices"):
        model_hash(object())


def test_provenance_of_records_the_errors_and_refuses_unknown_keys(dsms, reductions):
    _, _, res = reductions[1]
    errs = {"max_abs_error": 1e-3, "max_rel_error": 0.02, "band_peak": 0.2, "h2_error": float("inf"), "h2_floor": 1e-12,
            "hinf_error": 4e-3, "hinf_upper_bound": 4.1e-3, "hinf_certified": True,
            "norm_options": {"h2": {"rtol": 1e-8}}}
    p = provenance_of(dsms, "irka", {"tol": 1e-6}, res.info, errs, grid=(0.01, 1.0, 200), source="dsms:g=50")
    assert p["model"] == {"name": "dsms(g=50)", "source": "dsms:g=50", "hash": model_hash(dsms), "n1": 50, "n2": 1,
                          "m": 1, "p": 3, "band": [0.01, 1.0]}
    assert p["r"] == res.info["r"] and p["options"] == {"tol": 1e-6} and p["options_resolved"]["tol"] == 1e-6
    band = p["errors"]["band"]
    assert band["max_error_rel_peak"] == 1e-3 / 0.2 and band["grid"] == {"lo": 0.01, "hi": 1.0, "n": 200,
                                                                          "spacing": "log"}
    assert np.array_equal(grid_omega(band["grid"]), np.logspace(-2, 0, 200))
    assert p["errors"]["h2"]["options"] == {"rtol": 1e-8} and p["errors"]["hinf"]["upper_bound"] == 4.1e-3
    # strict JSON: the infinite H2 error is written as a string
    text = json.dumps(ms.utils.strict_json(p), allow_nan=False)
    assert json.loads(text)["errors"]["h2"]["error"] == "inf"
    w = np.array([0.1, 0.5, 2.0])  # not log-spaced: listed
    assert provenance_of(dsms, "irka", None, res.info, errs, grid=w)["errors"]["band"]["grid"] == {"omega": w.tolist()}
    with pytest.raises(ms.OptionError, match=r"unknown key\(s\) 'h2_eror'"):
        provenance_of(dsms, "irka", {}, res.info, {"h2_eror": 1.0})
    with pytest.raises(ms.InputError, match="grid is required with band errors"):
        provenance_of(dsms, "irka", {}, res.info, {"max_abs_error": 1.0})
    tol = {"tol": 0.01, "measure": "band", "status": "met"}
    assert provenance_of(dsms, "irka", {}, res.info, extra={"tolerance": tol})["tolerance"] == tol
    with pytest.raises(ms.InputError, match="extra may not replace the record's own key\\(s\\) 'model'"):
        provenance_of(dsms, "irka", {}, res.info, extra={"model": "x"})
    assert {"h2_floor", "h2_norm_floor", "hinf_norm_upper_bound", "norm_options"} <= set(ERROR_KEYS)


def _run(capsys, *argv):
    code = cli.main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_reduce_save_then_verify_agrees_and_tampering_fails(tmp_path, capsys):
    stem = tmp_path / "irka4"
    code, out, _ = _run(capsys, "reduce", "--model", "dsms:g=50", "--method", "irka", "--r", "4", "--save", str(stem),
                        "--json")
    rec = json.loads(out)
    assert code == 0 and rec["saved"] == [str(stem) + e for e in (".npz", ".mat", ".json")]
    side = read_sidecar(stem)
    errs = side["provenance"]["errors"]
    # the sidecar holds the numbers the command printed
    assert errs["band"]["max_abs_error"] == rec["max_abs_error"] and errs["h2"]["error"] == rec["h2_error"]
    assert errs["hinf"]["upper_bound"] == rec["hinf_upper_bound"] and errs["h2"]["floor"] > 0
    code, out, _ = _run(capsys, "verify", "dsms:g=50", str(stem) + ".mat", "--json")
    res = json.loads(out)
    assert code == 0 and res["agrees"] and res["failed"] == []
    rows = {r["quantity"]: r for r in res["rows"]}
    assert set(rows) == {"model hash", "band max error", "band peak", "band max relative error", "H2 error",
                         "H2 norm", "Hinf error", "Hinf norm"}
    assert all(r["agrees"] for r in rows.values())
    # the band error computed again from refined responses; the LU's own value differs at the rounding level
    assert abs(rows["band max error"]["recomputed"] - rec["max_abs_error"]) <= rows["band max error"]["accuracy"]
    assert rows["band max error"]["accuracy"] <= 1e-10 * rec["max_abs_error"]

    # a recorded value changed beyond its stated accuracy: exit 1, the quantity named
    def tamper(path, kind, key, factor):
        data = json.loads(path.read_text())
        data["provenance"]["errors"][kind][key] *= factor
        path.write_text(json.dumps(data))
    tamper(stem.with_suffix(".json"), "h2", "error", 1 + 1e-6)
    code, out, err = _run(capsys, "verify", "dsms:g=50", str(stem))
    assert code == 1 and "H2 error disagree" in err and "NOT verified: H2 error" in out
    tamper(stem.with_suffix(".json"), "h2", "error", 1 / (1 + 1e-6))
    tamper(stem.with_suffix(".json"), "band", "max_abs_error", 1 + 1e-6)
    code, out, err = _run(capsys, "verify", "dsms:g=50", str(stem), "--no-norms")
    assert code == 1 and "band max error" in err
    # another model: the hash differs, said so, and the verification fails
    code, out, err = _run(capsys, "verify", "dsms:g=51", str(stem), "--no-norms")
    assert code == 1 and "model hash" in err and "another model" in err


def test_no_norms_save_and_bad_input(tmp_path, capsys):
    stem = tmp_path / "bt"
    code, out, _ = _run(capsys, "reduce", "--model", "dsms:g=50", "--method", "bt", "--r", "6", "--no-norms",
                        "--save", str(stem) + ".npz", "--json")
    assert code == 0 and json.loads(out)["saved"][0] == str(stem) + ".npz"
    errs = read_sidecar(stem)["provenance"]["errors"]
    assert errs["h2"] is None and errs["hinf"] is None and errs["norms"] == "not computed (--no-norms)"
    code, out, _ = _run(capsys, "verify", "dsms:g=50", str(stem))
    assert code == 0 and "not recorded (not computed (--no-norms))" in out
    # bad input: exit 2 naming what is wrong
    code, _, err = _run(capsys, "verify", "dsms:g=50", str(tmp_path / "none.npz"))
    assert code == 2 and "none.npz" in err and "does not exist" in err
    load_rom(stem).save(tmp_path / "bare.npz")  # the matrices alone, no sidecar
    code, _, err = _run(capsys, "verify", "dsms:g=50", str(tmp_path / "bare.npz"))
    assert code == 2 and "no sidecar" in err
    code, _, err = _run(capsys, "verify", "nomodel:g=1", str(stem))
    assert code == 2 and "nomodel" in err
    code, _, err = _run(capsys, "verify", "random:m=2", str(stem))  # other inputs: fails, not refused
    assert code == 1 and "inputs and outputs" in err
    with pytest.raises(SystemExit) as exc:
        cli.main(["verify", "dsms:g=50"])
    assert exc.value.code == 2 and "romfile" in capsys.readouterr().err


@pytest.mark.parametrize("index", [0, 1, 2, 3], ids=["bt-simo", "irka-simo", "bt-mimo", "irka-mimo"])
def test_to_control_has_the_transfer_function(reductions, index):
    """python-control's system of `to_control()` equals the reduced model's transfer function at points of the
    right half-plane and of the imaginary axis, to the rounding of E^-1 and of the two solves."""
    _, _, res = reductions[index]
    rom = res.rom
    sys_ = rom.to_control()
    E, A, B, C, D = rom._first_order_arrays()
    n = A.shape[0]
    kE = np.linalg.cond(E)
    At = np.linalg.solve(E, A)
    assert sys_.nstates == rom.states and (sys_.ninputs, sys_.noutputs) == (rom.m, rom.p)
    for s in (0.05j, 0.3 + 0.9j, 2.0j, 1.5):
        H = rom.transfer(s)
        Hc = np.asarray(sys_(s)).reshape(H.shape)
        # the ROM's own solve, control's solve with sI - E^-1 A, and E^-1 applied (kappa(E) eps relative)
        tol = (transfer_tolerance(s * E - A, B, C) + transfer_tolerance(s * np.eye(n) - At, np.linalg.solve(E, B), C)
               * (1 + kE * np.linalg.norm(At, 2) / np.linalg.norm(s * np.eye(n) - At, 2)))
        assert_rounding(np.linalg.norm(Hc - H) / np.linalg.norm(H), tol, f"to_control at s = {s}")
