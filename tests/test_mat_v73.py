"""MATLAB v7.3 files (HDF5 after a 512-byte MATLAB header, arrays stored transposed) load
exactly like the v5 file of the same data, through the same mapping paths (issue 23 item 6).
The v7.3 file is written here with h5py the way MATLAB lays it out: a userblock starting
"MATLAB 7.3 MAT-file", one dataset per variable with its MATLAB_class, the dimensions of
MATLAB's column-major arrays reversed, structs as groups, text as uint16, cells as
references into "#refs#"."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
import scipy.io

from ident import DataError
from ident.loaders import _read_mat, load_experiment, parse_mapping, resolve_path
from ident.robot.loaders import load_robot_runs


def _matlab_header() -> bytes:
    text = (b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Thu Nov 26 12:00:00 2026 "
            b"HDF5 schema 1.00 .")
    return text.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM"


def _put(parent: h5py.Group, name: str, value, f: h5py.File) -> None:
    """Write ``value`` as MATLAB 7.3 does: dict -> struct group, str -> char, list -> cell,
    arrays as 2-D (a vector is 1 x N) in MATLAB's column-major order (HDF5 dims reversed)."""
    if isinstance(value, dict):
        g = parent.create_group(name)
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        for k, v in value.items():
            _put(g, k, v, f)
        return
    if isinstance(value, str):
        codes = np.array([[ord(c) for c in value]], dtype=np.uint16)  # 1 x n
        ds = parent.create_dataset(name, data=codes.T)
        ds.attrs["MATLAB_class"] = np.bytes_("char")
        return
    if isinstance(value, list):
        refs = f.require_group("#refs#")
        out = np.empty((len(value), 1), dtype=h5py.ref_dtype)  # 1 x n cell, transposed
        for i, v in enumerate(value):
            key = f"{name}_{i}"
            _put(refs, key, v, f)
            out[i, 0] = refs[key].ref
        ds = parent.create_dataset(name, data=out, dtype=h5py.ref_dtype)
        ds.attrs["MATLAB_class"] = np.bytes_("cell")
        return
    a = np.asarray(value)
    a = a.reshape(1, -1) if a.ndim < 2 else a  # MATLAB: at least 2-D, vectors as rows
    ds = parent.create_dataset(name, data=a.T)  # column-major: HDF5 holds the transpose
    ds.attrs["MATLAB_class"] = np.bytes_({"f": "double", "i": "int32", "b": "logical",
                                          "u": "uint8"}[a.dtype.kind])


def write_mat_v73(path, variables: dict) -> None:
    with h5py.File(path, "w", userblock_size=512) as f:
        for k, v in variables.items():
            _put(f, k, v, f)
    with open(path, "r+b") as fh:
        fh.write(_matlab_header())


def _data(n=600, dt=2e-3):
    t = np.arange(n) * dt
    pos = np.vstack([0.3 * np.sin((k + 1) * 2.0 * t) for k in range(3)]) * 180 / np.pi  # [deg]
    tor = np.vstack([5.0 * np.cos((k + 1) * 2.0 * t) + k for k in range(3)])
    return {
        "rec": {"time": t, "pos_deg": pos, "torque": tor},
        "para": {"u": np.array([100.0, 120.0, 80.0]), "k": 0.5},
        "gtau": 2.5,
        "traj_name": "excitation A",
        "flags": np.array([True, False, True]),
    }


def _both(tmp_path):
    data = _data()
    v5, v73 = tmp_path / "v5.mat", tmp_path / "v73.mat"
    scipy.io.savemat(v5, data)
    write_mat_v73(v73, data)
    assert v73.read_bytes()[:19] == b"MATLAB 7.3 MAT-file" and h5py.is_hdf5(v73)
    with pytest.raises(NotImplementedError):  # what scipy says of it: it is v7.3 indeed
        scipy.io.loadmat(v73)
    return v5, v73


def test_v73_reads_like_v5(tmp_path):
    v5, v73 = _both(tmp_path)
    a, b = _read_mat(v5), _read_mat(v73)
    assert sorted(a) == sorted(b)
    for spec in ("rec.time", "rec.pos_deg", "rec.torque[2]", "rec.pos_deg[:, 10]", "para.u",
                 "para.u[1]", "para.k", "gtau", "flags"):
        x, y = resolve_path(a, spec), resolve_path(b, spec)
        assert x.shape == y.shape, spec
        np.testing.assert_array_equal(x, y, err_msg=spec)
    assert b["traj_name"] == a["traj_name"] == "excitation A"
    assert sorted(b["rec"]._fieldnames) == sorted(a["rec"]._fieldnames)
    with pytest.raises(DataError, match="'traj_name' is text, not numeric"):
        resolve_path(b, "traj_name", "v73.mat")


def test_v73_experiment_equals_v5(tmp_path):
    v5, v73 = _both(tmp_path)
    m = parse_mapping("t=rec.time,q=rec.pos_deg[1],tau=rec.torque[1]")
    kw = dict(mapping=m, gain="para.u[1]*para.k", q_unit="deg")
    e5, e73 = load_experiment(v5, **kw), load_experiment(v73, **kw)
    for k in ("t", "q", "tau"):
        np.testing.assert_array_equal(getattr(e5, k), getattr(e73, k))
    np.testing.assert_allclose(e73.tau, 60.0 * (5.0 * np.cos(4.0 * e73.t) + 1))


def test_v73_robot_runs_equal_v5(tmp_path):
    v5, v73 = _both(tmp_path)
    m = {"t": "rec.time", "q": "rec.pos_deg", "tau": "rec.torque"}
    r5, r73 = (load_robot_runs([p], ("j1", "j2", "j3"), mapping=m, q_unit="deg")[0]
               for p in (v5, v73))
    np.testing.assert_array_equal(r5.q, r73.q)
    np.testing.assert_array_equal(r5.tau, r73.tau)


def test_v73_cells_and_broken_files(tmp_path):
    p = tmp_path / "cells.mat"
    write_mat_v73(p, {"c": [np.arange(3.0), "txt"], "x": 1.5})
    got = _read_mat(p)
    np.testing.assert_array_equal(got["c"][0], np.arange(3.0))
    assert got["c"][1] == "txt" and got["x"] == 1.5
    bad = tmp_path / "bad.mat"
    bad.write_bytes(_matlab_header() + b"\0" * 400)  # v7.3 header, no HDF5 behind it
    with pytest.raises(DataError, match=r"bad.mat: not a readable MATLAB v7.3"):
        _read_mat(bad)
