"""The installed facesim package against the command line's files (docs/guide/python.md)."""

import ast
import csv
import json
import math
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

import facesim
from conftest import cli

TOL_MM = 1e-9

PLAN_TOML = """
[[osteotomy]]
name = "mandible"
region = { box = { min = [-70.0, -75.0, -125.0], max = [70.0, -1.5, -26.5] } }
translate = [0.0, -3.0, 1.0]
rotate_deg = [2.0, 0.0, 0.0]
pivot = [0.0, -40.0, -60.0]
"""

SWEEP_TOML = """
[[plan]]
label = "advance 4, turn"
[[plan.move]]
segment = "mandible"
translate = [0, -4, 0]
rotate_deg = [1, 0, 0]

[grid]
segment = "mandible"
translate_y = { from = 0, to = -8, steps = 3 }
rotate_x = { from = 0, to = 2, steps = 2 }
"""

PLY_TYPES = {"char": "i1", "uchar": "u1", "short": "<i2", "ushort": "<u2", "int": "<i4",
             "uint": "<u4", "float": "<f4", "double": "<f8"}


def read_ply(path: Path):
    """Vertices (n, 3) and triangles (m, 3) of a binary little-endian PLY as facesim writes
    it (vertex scalars, then `list uchar int vertex_indices`): a reader independent of
    facesim's."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    assert "format binary_little_endian 1.0" in header
    elements, current = [], None
    for line in header:
        w = line.split()
        if w[0] == "element":
            current = (w[1], int(w[2]), [])
            elements.append(current)
        elif w[0] == "property" and w[1] != "list":
            current[2].append((w[2], PLY_TYPES[w[1]]))
    (vname, nv, vprops), (fname, nf, _) = elements[0], elements[1]
    assert (vname, fname) == ("vertex", "face")
    vdt = np.dtype(vprops)
    v = np.frombuffer(data, vdt, nv, end)
    fdt = np.dtype([("n", "u1"), ("i", "<i4", 3)])
    f = np.frombuffer(data, fdt, nf, end + nv * vdt.itemsize)
    assert (f["n"] == 3).all()
    return np.stack([v["x"], v["y"], v["z"]], axis=1), f["i"].astype(np.int64)


def read_ply_vertex_properties(path: Path):
    """The vertex element of a binary little-endian PLY as a numpy structured array."""
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    props, n = [], None
    for line in data[:end].decode().splitlines():
        w = line.split()
        if w[0] == "element":
            if n is not None:
                break
            n = int(w[2])
        elif w[0] == "property" and w[1] != "list":
            props.append((w[2], PLY_TYPES[w[1]]))
    return np.frombuffer(data, np.dtype(props), n, end)


def test_band_equals_face_band_ply(case_dir, tmp_path):
    import tomllib

    case = tomllib.loads((case_dir / "case.toml").read_text())
    case["uncertainty"] = {"samples": 3, "seed": 2}
    r = facesim.run(case, out=tmp_path / "out", base_dir=case_dir)
    v = read_ply_vertex_properties(tmp_path / "out" / "face_band.ply")
    assert set(r.band) == {"mean", "p05", "p95"}
    for k in ("mean", "p05", "p95"):
        assert r.band[k].shape == r.displacement.shape
        assert np.abs(r.band[k] - v[k]).max() <= 1e-5  # float32 in the file
    assert (r.band["p05"] <= r.band["p95"] + 1e-9).all()
    assert r.report["uncertainty"]["samples"] == 3


def test_replan_band_from_the_stored_reduced_model(case_dir, tmp_path):
    """PLAN.toml's [uncertainty] samples the run's reduced_model.bin: the run's own band."""
    import tomllib

    case = tomllib.loads((case_dir / "case.toml").read_text())
    case.setdefault("tet", {}).update({"skin_size_mm": 6.0, "deep_size_mm": 12.0, "error_estimate": False})
    u = {"samples": 5, "seed": 3, "method": "reduced"}
    case["uncertainty"] = u
    r = facesim.run(case, out=tmp_path / "out", base_dir=case_dir)
    assert (tmp_path / "out" / "reduced_model.bin").is_file()
    p = facesim.replan(r.out_dir, {"uncertainty": u}, out=tmp_path / "band")
    assert p.band is not None and set(p.band) == {"mean", "p05", "p95"}
    for k in ("mean", "p05", "p95"):
        assert np.array_equal(p.band[k], r.band[k]), k
    assert p.report["uncertainty"]["largest_bound_mm"] == r.report["uncertainty"]["largest_bound_mm"]
    plain = facesim.replan(r.out_dir, {"osteotomy": []}, out=tmp_path / "plain")
    assert plain.band is None


def read_displacement_csv(path: Path):
    rows = np.loadtxt(path, delimiter=",", skiprows=1)
    return rows[:, 1:4], rows[:, 4:7], rows[:, 7]


def markups(path: Path):
    d = json.loads(path.read_text())
    return {p["label"]: np.array(p["position"]) for p in d["markups"][0]["controlPoints"]}


def assert_equals_files(r, out: Path, pre_dir: Path = None):
    """r's arrays equal face_pre/face_post.ply and displacement.csv in `out` to 1e-9 mm
    (face_pre.ply from `pre_dir` when given: a replan writes none)."""
    pre, tri = read_ply((pre_dir or out) / "face_pre.ply")
    post, tri_post = read_ply(out / "face_post.ply")
    assert r.vertices_pre.shape == pre.shape and r.vertices_post.shape == post.shape
    assert np.abs(r.vertices_pre - pre).max() <= TOL_MM
    assert np.abs(r.vertices_post - post).max() <= TOL_MM
    np.testing.assert_array_equal(r.triangles, tri)
    np.testing.assert_array_equal(r.triangles, tri_post)
    c_pre, c_post, dist = read_displacement_csv(out / "displacement.csv")
    assert np.abs(r.vertices_pre - c_pre).max() <= TOL_MM
    assert np.abs(r.vertices_post - c_post).max() <= TOL_MM
    assert np.abs(r.displacement - dist).max() <= TOL_MM


def test_arrays_have_the_documented_dtypes_and_shapes(dict_run):
    r = dict_run[0]
    n = r.vertices_pre.shape[0]
    assert r.vertices_pre.dtype == np.float64 and r.vertices_pre.shape == (n, 3)
    assert r.vertices_post.dtype == np.float64 and r.vertices_post.shape == (n, 3)
    assert r.triangles.dtype == np.int64 and r.triangles.shape[1] == 3
    assert r.triangles.min() >= 0 and r.triangles.max() < n
    assert r.displacement.dtype == np.float64 and r.displacement.shape == (n,)
    # The phantom's mandible moves 6 mm forward (-y): the face follows, no further.
    assert 1.0 < r.displacement.max() <= 6.0 + 1e-6
    assert r.band is None  # no [uncertainty] in the case
    assert isinstance(r.report, dict) and "FacesimError" in dir(facesim)


def test_run_of_a_dict_equals_the_command_line(dict_run, cli_out):
    assert_equals_files(dict_run[0], cli_out)


def test_run_of_a_path_equals_the_command_line(path_run, cli_out):
    assert_equals_files(path_run, cli_out)


def test_run_equals_its_own_files_and_report(dict_run):
    r = dict_run[0]
    out = Path(r.out_dir)
    assert_equals_files(r, out)
    assert r.report == json.loads((out / "report.json").read_text())


def test_landmarks_equal_the_markups_files(dict_run, cli_out):
    r = dict_run[0]
    pre, post = markups(cli_out / "landmarks_pre.mrk.json"), markups(cli_out / "landmarks_post.mrk.json")
    assert pre and set(r.landmarks) == set(pre) == set(post)
    for label, lm in r.landmarks.items():
        assert lm["pre"].shape == (3,) and lm["pre"].dtype == np.float64
        assert np.abs(lm["pre"] - pre[label]).max() <= TOL_MM
        assert np.abs(lm["post"] - post[label]).max() <= TOL_MM
        assert abs(lm["change_mm"] - np.linalg.norm(lm["post"] - lm["pre"])) <= TOL_MM


def test_the_interpreter_lock_is_released_while_run_works(dict_run):
    _, ticks, start, end = dict_run
    assert end - start > 1.5, "the run was too short to tell"
    inside = [t for t in ticks if start + 0.5 < t < end - 0.5]
    # Holding the lock, the ticking thread could not run at all inside the call.
    assert len(inside) >= 20, f"{len(inside)} ticks during {end - start:.1f} s of run"


def test_replan_equals_the_command_line(dict_run, cli_out, tmp_path):
    import tomllib

    plan_file = tmp_path / "plan.toml"
    plan_file.write_text(PLAN_TOML)
    cli("replan", cli_out, plan_file, "--out", tmp_path / "cli-replan")
    from_dict = facesim.replan(dict_run[0].out_dir, tomllib.loads(PLAN_TOML), out=tmp_path / "py-replan")
    from_file = facesim.replan(dict_run[0].out_dir, plan_file, out=tmp_path / "py-replan-file")
    cli_post = markups(tmp_path / "cli-replan" / "landmarks_post.mrk.json")
    for r in (from_dict, from_file):
        assert r.band is None
        # The run's landmarks carried with the new plan, as the command line writes them.
        assert set(r.landmarks) == set(cli_post) and len(cli_post) > 0
        for label, p in cli_post.items():
            assert np.abs(r.landmarks[label]["post"] - p).max() <= TOL_MM
        assert r.report["replan"]["exact"] is True
        assert_equals_files(r, tmp_path / "cli-replan", pre_dir=cli_out)
    assert r.displacement.max() > 1.0


def test_replan_of_the_runs_plan_is_the_run(dict_run, case_dir, tmp_path):
    """Independent of replan's own output: the volumetric model's basis is exact, so replanning
    the case's own plan gives the full run's face."""
    import tomllib

    case = tomllib.loads((case_dir / "case.toml").read_text())
    r = facesim.replan(dict_run[0].out_dir, {"osteotomy": case["osteotomy"]}, out=tmp_path)
    assert np.abs(r.vertices_post - dict_run[0].vertices_post).max() <= 1e-6


def test_sweep_equals_the_command_line(dict_run, cli_out, tmp_path):
    import tomllib

    sweep_file = tmp_path / "sweep.toml"
    sweep_file.write_text(SWEEP_TOML)
    cli("sweep", cli_out, sweep_file, "--out", tmp_path / "cli-sweep")
    cols = facesim.sweep(dict_run[0].out_dir, tomllib.loads(SWEEP_TOML), out=tmp_path / "py-sweep")
    with open(tmp_path / "cli-sweep" / "sweep.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 7 and list(cols) == list(rows[0])
    assert cols["label"] == [r["label"] for r in rows]
    assert cols["plan"].dtype == np.int64 and list(cols["plan"]) == [int(r["plan"]) for r in rows]
    for name, values in cols.items():
        if name in ("plan", "label"):
            continue
        assert values.dtype == np.float64 and values.shape == (7,)
        for v, row in zip(values, rows):
            cell = row[name]
            if cell == "":
                assert math.isnan(v), name
            else:
                assert abs(v - float(cell)) <= 5e-7 + 1e-12, (name, v, cell)
    # With `out`, the same files as the command line.
    assert (tmp_path / "py-sweep" / "sweep.csv").read_text() == (tmp_path / "cli-sweep" / "sweep.csv").read_text()
    # The grid's first plan moves nothing.
    assert cols["face_max_mm"][1] == 0.0 and cols["face_max_mm"][0] > 1.0


def test_a_bad_case_raises_facesim_error_with_the_command_lines_message(case_dir, tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    text = (case_dir / "case.toml").read_text().replace('path = "ct.nii.gz"', 'path = "no-such-ct.nii.gz"')
    (bad / "case.toml").write_text(text)
    (bad / "face.ply").write_bytes((case_dir / "face.ply").read_bytes())
    p = cli("run", bad, check=False)
    assert p.returncode != 0
    with pytest.raises(facesim.FacesimError) as e:
        facesim.run(bad)
    assert "no-such-ct.nii.gz" in str(e.value)
    assert p.stderr.strip().splitlines()[-1] == f"facesim: {e.value}"
    assert issubclass(facesim.FacesimError, Exception)
    assert not (bad / "out").exists(), "nothing written for a bad case"


def test_a_bad_dict_names_the_dict_and_the_key(case_dir):
    import tomllib

    case = tomllib.loads((case_dir / "case.toml").read_text())
    case["surface"]["alpha"] = None
    with pytest.raises(facesim.FacesimError, match=r"<case dict>: key 'surface.alpha' holds None"):
        facesim.run(case, base_dir=case_dir)
    case["surface"]["alpha"] = -1.0
    with pytest.raises(facesim.FacesimError, match=r"<case dict>.*alpha"):
        facesim.run(case, base_dir=case_dir)


def test_a_bad_plan_names_the_plan(dict_run, tmp_path):
    bad = tmp_path / "plan.toml"
    bad.write_text('[[osteotomy]]\nname = "maxilla"\nregion = { box = { min = [0, 0, 0], max = [1, 1, 1] } }\n')
    with pytest.raises(facesim.FacesimError, match=str(bad)):
        facesim.replan(dict_run[0].out_dir, bad, out=tmp_path / "o")
    with pytest.raises(facesim.FacesimError, match="no-such-run"):
        facesim.replan(tmp_path / "no-such-run", bad)


def test_the_stubs_describe_the_module():
    files = resources.files("facesim")
    assert files.joinpath("py.typed").is_file()
    stubs = ast.parse(files.joinpath("__init__.pyi").read_text())
    names = {n.name for n in stubs.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    helpers = {"Landmark", "Band"}  # TypedDicts of the stubs only
    assert names - helpers <= set(dir(facesim)), names - set(dir(facesim))
    assert set(facesim.__all__) - {"__version__"} <= names
    result = next(n for n in stubs.body if isinstance(n, ast.ClassDef) and n.name == "Result")
    props = {n.name for n in result.body if isinstance(n, ast.FunctionDef)}
    real = {a for a in dir(facesim.Result) if not a.startswith("_")}
    assert props == real
