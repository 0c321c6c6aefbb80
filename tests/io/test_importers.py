"""Importers: point clouds (PLY, XYZ, PCD ascii/binary, NPZ), contact CSVs, voxel averaging."""

import warnings

import numpy as np
import pytest
import trimesh

from torch_gpioius.io.datasets import DatasetError
from torch_gpioius.io.importers import dataset_from_files, load_contacts_csv, load_point_cloud, read_contacts_csv
from torch_gpioius.geometry.voxels import voxel_average
from torch_gpioius.models.estimator import EstimatorSettings
from torch_gpioius.models.overrides import EstimatorOverrides

PTS = np.array([[0.01, 0.02, 0.03], [0.04, -0.05, 0.06], [0.2, 0.1, -0.3], [0.021, 0.022, 0.023]])


def write_pcd(path, pts, binary):
    head = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
            f"WIDTH {len(pts)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(pts)}\n")
    data = np.c_[pts, np.ones(len(pts))].astype("<f4")
    if binary:
        path.write_bytes((head + "DATA binary\n").encode() + data.tobytes())
    else:
        path.write_text(head + "DATA ascii\n" + "\n".join(" ".join(f"{v:.6f}" for v in r) for r in data))


@pytest.mark.parametrize("fmt", ["ply", "xyz", "pcd-ascii", "pcd-binary", "npz"])
def test_point_cloud_formats(tmp_path, fmt):
    if fmt == "ply":
        p = tmp_path / "c.ply"
        trimesh.PointCloud(PTS).export(p)
    elif fmt == "xyz":
        p = tmp_path / "c.xyz"
        np.savetxt(p, PTS)
    elif fmt.startswith("pcd"):
        p = tmp_path / "c.pcd"
        write_pcd(p, PTS, binary=fmt.endswith("binary"))
    else:
        p = tmp_path / "c.npz"
        np.savez(p, points=PTS)
    got = load_point_cloud(p)
    assert got.shape == (4, 3) and np.allclose(got, PTS, atol=1e-6)
    assert np.allclose(load_point_cloud(p, units="cm"), PTS / 100, atol=1e-8)


def test_point_cloud_errors(tmp_path):
    np.savez(tmp_path / "a.npz", points=np.full((3, 3), np.nan))
    with pytest.raises(DatasetError, match="no \\(finite\\) points"):
        load_point_cloud(tmp_path / "a.npz")
    np.savez(tmp_path / "b.npz", points=np.c_[PTS[:2].T, [0, 0, np.inf]].T)
    with pytest.raises(DatasetError, match="NaN or inf"):
        load_point_cloud(tmp_path / "b.npz", drop_nonfinite=False)
    np.savez(tmp_path / "c.npz", pts=PTS)
    with pytest.raises(DatasetError, match="'points'"):
        load_point_cloud(tmp_path / "c.npz")
    (tmp_path / "d.pcd").write_text("VERSION 0.7\nFIELDS x y\n")
    with pytest.raises(DatasetError, match="d.pcd"):
        load_point_cloud(tmp_path / "d.pcd")
    (tmp_path / "e.ply").write_bytes(b"ply\nformat garbage\n")
    with pytest.raises(DatasetError, match="e.ply"):
        load_point_cloud(tmp_path / "e.ply")
    with pytest.raises(DatasetError, match="unknown point-cloud format"):
        load_point_cloud(tmp_path / "f.obj2")
    with pytest.raises(DatasetError, match="units"):
        load_point_cloud(tmp_path / "a.npz", units="inch")


def test_voxel_average_by_hand():
    pts = np.array([[0.01, 0.01, 0.01], [0.03, 0.04, 0.02], [0.07, 0.01, 0.01], [-0.01, 0.0, 0.0]])
    got = voxel_average(pts, 0.05)
    # voxels: (0,0,0) holds the first two, (1,0,0) the third, (-1,0,0) the last
    want = {(-1, 0, 0): [-0.01, 0.0, 0.0], (0, 0, 0): [0.02, 0.025, 0.015], (1, 0, 0): [0.07, 0.01, 0.01]}
    assert len(got) == 3
    for row in got:
        key = tuple(np.floor(row / 0.05).astype(int))
        assert np.allclose(row, want[key])


def test_contacts_csv(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("x,y,z,label,step\n1,2,3,contact,0\n4,5,6,free,2\n7,8,9,1,3\n")
    x, y, step = load_contacts_csv(p, units="mm")
    assert np.allclose(x, [[0.001, 0.002, 0.003], [0.004, 0.005, 0.006], [0.007, 0.008, 0.009]])
    assert y.tolist() == [0, 1, 1] and step.tolist() == [0, 2, 3]
    for body, match in [("x,y,label\n1,nan,contact\n", "NaN"), ("x,y,label\n1,2,touch\n", "c.csv:2: label"),
                        ("x,y,label\n1,a,contact\n", "not numbers"), ("x,label\n1,contact\n", "header"),
                        ("x,y,label\n", "no rows"), ("x,y,label,step\n1,2,free,1.5\n", "step")]:
        p.write_text(body)
        with pytest.raises(DatasetError, match=match):
            load_contacts_csv(p)


def test_inside_points_in_a_contacts_csv(tmp_path):
    """A point known to lie inside: `inside` with its depth in the file's units (20 mm -> y = -0.02 / 0.05 = -0.4,
    the label the exploration gives the point behind a contact), or a negative label directly; they reach the model
    as labels below zero. Every way to get it wrong is named by file and line."""
    p = tmp_path / "c.csv"
    p.write_text("x,y,z,label,depth\n100,0,0,contact,\n100,0,-20,inside,20\n100,0,-10,-0.2,\n100,0,40,free,\n")
    x, y, _ = load_contacts_csv(p, units="mm")
    np.testing.assert_allclose(y, [0.0, -0.4, -0.2, 1.0], rtol=1e-15)
    np.savez(tmp_path / "cloud.npz", points=PTS * 1000 + [100, 0, 0])          # millimetres, around the contacts
    ds = dataset_from_files(p, tmp_path / "cloud.npz", units="mm",
                            settings=EstimatorOverrides(voxel=0, labels={"contact_repeats": 1}))
    assert ds.y[:4].tolist() == y.tolist()
    assert float(ds.to_model().train_targets.min()) == pytest.approx(-0.4, rel=1e-15)
    for body, match in [("x,y,label,depth\n1,2,inside,\n", "c.csv:2: an inside point needs its depth"),
                        ("x,y,label\n1,2,inside\n", "c.csv:2: an inside point needs its depth"),
                        ("x,y,label,depth\n1,2,inside,0\n", "c.csv:2: depth '0' must be a positive"),
                        ("x,y,label,depth\n1,2,inside,-1\n", "must be a positive"),
                        ("x,y,label,depth\n1,2,inside,nan\n", "must be a positive"),
                        ("x,y,label,depth\n1,2,contact,5\n", "c.csv:2: depth '5' is given for a 'contact' row"),
                        ("x,y,label\n1,2,0.5\n", "or a negative number"),
                        ("x,y,label\n1,2,-inf\n", "or a negative number")]:
        p.write_text(body)
        with pytest.raises(DatasetError, match=match):
            load_contacts_csv(p)


def test_dataset_from_files(tmp_path):
    (tmp_path / "c.csv").write_text("x,y,z,label\n0.1,0,0,contact\n0.3,0,0,free\n")
    np.savez(tmp_path / "cloud.npz", points=PTS)
    ds = dataset_from_files(tmp_path / "c.csv", tmp_path / "cloud.npz", settings=EstimatorOverrides(voxel=0))
    k = EstimatorSettings.default().labels.contact_repeats                # the contact as often as a run counts it
    assert len(ds) == 5 + k and ds.task.tolist() == [0] * (k + 1) + [1] * 4
    assert ds.y.tolist() == [0] * k + [1, 0, 0, 0, 0]
    (tmp_path / "c2.csv").write_text("x,y,label\n0.1,0,contact\n")
    with pytest.raises(DatasetError, match="3-D"):
        dataset_from_files(tmp_path / "c2.csv", tmp_path / "cloud.npz")


def test_a_users_contacts_enter_as_often_as_an_exploration_repeats_them(tmp_path):
    """``contact_repeats``: each contact row of the files k times, as an exploration records it (its free space and
    inside points once), with the contact's step."""
    (tmp_path / "c.csv").write_text("x,y,z,label,step\n0.1,0,0,contact,1\n0.3,0,0,free,1\n0.1,0.01,0,contact,2\n")
    np.savez(tmp_path / "cloud.npz", points=PTS)
    ds = dataset_from_files(tmp_path / "c.csv", tmp_path / "cloud.npz",
                            settings=EstimatorOverrides(voxel=0, labels={"contact_repeats": 3}))
    inner = ds.task == 0
    assert ds.y[inner].tolist() == [0, 0, 0, 1, 0, 0, 0]
    np.testing.assert_array_equal(ds.x[inner][:3], np.repeat([[0.1, 0.0, 0.0]], 3, axis=0))
    assert ds.step[inner].tolist() == [1, 1, 1, 1, 2, 2, 2]


# ------------------------------------------------------------------------------------------ issue 14: importers
def test_csv_rows_with_extra_or_missing_fields_are_named(tmp_path):
    (tmp_path / "a.csv").write_text("x,y,label\n0.1,0.2,contact\n0.1,0.2,contact,oops\n")
    with pytest.raises(DatasetError, match="a.csv:3: .*more fields"):
        load_contacts_csv(tmp_path / "a.csv")
    (tmp_path / "b.csv").write_text("x,y,label\n0.1,0.2\n")
    with pytest.raises(DatasetError, match="b.csv:2: .*fewer fields"):
        load_contacts_csv(tmp_path / "b.csv")


def test_ply_with_a_wrong_or_negative_vertex_count_is_refused(tmp_path):
    p = tmp_path / "ok.ply"
    trimesh.PointCloud(PTS).export(p)                  # binary, exact: accepted
    assert load_point_cloud(p).shape == (4, 3)
    p.write_bytes(p.read_bytes() + b"\x00" * 12)       # one row more than declared
    with pytest.raises(DatasetError, match="vertices"):
        load_point_cloud(p)
    rows = "\n".join(" ".join(f"{v}" for v in r) for r in PTS)
    for n in (-2, 2, 10):
        p = tmp_path / f"v{n}.ply"
        p.write_text(f"ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n"
                     f"property float z\nend_header\n{rows}\n")
        with pytest.raises(DatasetError, match="vertices|vertex count"):
            load_point_cloud(p)


@pytest.mark.parametrize("binary", [False, True])
def test_pcd_whose_body_disagrees_with_points_is_refused(tmp_path, binary):
    p = tmp_path / "c.pcd"
    write_pcd(p, np.tile(PTS, (13, 1))[:50], binary=binary)
    text = p.read_bytes().replace(b"POINTS 50", b"POINTS 10")
    p.write_bytes(text)
    with pytest.raises(DatasetError, match="POINTS 10"):
        load_point_cloud(p)


@pytest.mark.parametrize("voxel", [float("inf"), 1e-300, 0.0, -0.05, float("nan"), True])
def test_voxel_sizes_that_collapse_or_skip_are_refused(tmp_path, voxel):
    np.savez(tmp_path / "c.npz", points=np.random.default_rng(0).uniform(-0.3, 0.3, (50, 3)))
    with pytest.raises(DatasetError, match="voxel"):
        load_point_cloud(tmp_path / "c.npz", voxel=voxel)
    with pytest.raises(ValueError, match="voxel"):
        voxel_average(np.zeros((5, 3)), voxel)
    assert len(load_point_cloud(tmp_path / "c.npz", voxel=None)) == 50


def test_complex_and_boolean_points_are_refused(tmp_path):
    np.savez(tmp_path / "c.npz", points=PTS + 1j)
    with pytest.raises(DatasetError, match="real numbers"):
        load_point_cloud(tmp_path / "c.npz")
    np.savez(tmp_path / "b.npz", points=PTS > 0)
    with pytest.raises(DatasetError, match="real numbers"):
        load_point_cloud(tmp_path / "b.npz")


def test_dataset_from_files_validates_its_parameters(tmp_path):
    (tmp_path / "a.csv").write_text("x,y,label\n0.1,0.2,contact\n")
    with pytest.raises(ValueError, match="noise"):
        dataset_from_files(tmp_path / "a.csv", settings=EstimatorOverrides(noise=-1))
    with pytest.raises(ValueError, match="settings: must be one of"):
        dataset_from_files(tmp_path / "a.csv", settings="mine")


# ------------------------------------------------------------------------------- issue 33: units, columns, steps
def test_contacts_and_clouds_in_millimetres_are_refused_naming_the_units(tmp_path):
    """Issue 33, item 6: contacts written in mm gave a dataset 500 "m" across, without a word."""
    mm = tmp_path / "touch_mm.csv"
    mm.write_text("x,y,z,label\n100,0,0,contact\n250,30,0,free\n-200,0,40,contact\n")
    with pytest.raises(DatasetError, match=r"touch_mm.csv: the points are 450 m across.*millimetres.*units='mm'"):
        load_contacts_csv(mm)
    x, _, _ = load_contacts_csv(mm, units="mm")
    assert np.allclose(x[0], [0.1, 0, 0])
    np.savez(tmp_path / "cloud_mm.npz", points=PTS * 1000)             # the same scene, in mm
    with pytest.raises(DatasetError, match="cloud_mm.npz: .*probably in millimetres"):
        load_point_cloud(tmp_path / "cloud_mm.npz")
    with pytest.raises(DatasetError, match="touch_mm.csv"):
        dataset_from_files(mm, tmp_path / "cloud_mm.npz")
    one_each = EstimatorOverrides(voxel=0, labels={"contact_repeats": 1})
    assert len(dataset_from_files(mm, tmp_path / "cloud_mm.npz", units="mm", settings=one_each)) == 7


def test_a_dataset_in_millimetres_is_refused_wherever_it_is_built(tmp_path):
    from torch_gpioius.io.datasets import Dataset, load_dataset, save_dataset

    x = np.array([[0.0, 0.0], [120.0, 0.0], [0.0, 80.0]])
    with pytest.raises(DatasetError, match="field 'x': the points are 120 m across.*metres"):
        Dataset(x, np.zeros(3), np.zeros(3, np.int64), np.zeros(3, np.int64))
    with pytest.raises(DatasetError, match="60.1 m from the origin"):     # small, but far out: not metres either
        Dataset(np.array([[60.0, 0.0], [60.1, 0.0]]), np.zeros(2), np.zeros(2, np.int64), np.zeros(2, np.int64))
    ok = save_dataset(
        Dataset(x / 1000, np.zeros(3), np.zeros(3, np.int64), np.zeros(3, np.int64)), tmp_path / "m.gpioius"
    )
    assert len(load_dataset(ok)) == 3


def test_a_csv_with_a_column_twice_is_refused(tmp_path):
    """Issue 33, item 10: `x,y,label,X` or `label,label`: the last column won."""
    for header, row in (("x,y,label,X", "0.1,0.2,contact,0.9"), ("x,y,label,label", "0.1,0.2,contact,free")):
        (tmp_path / "d.csv").write_text(f"{header}\n{row}\n")
        with pytest.raises(DatasetError, match=r"d.csv: the header names column\(s\) \['(x|label)'\] more than once"):
            load_contacts_csv(tmp_path / "d.csv")


def test_a_step_too_large_for_the_format_names_file_and_line(tmp_path):
    """Issue 33, item 13: a bare OverflowError named neither the file nor the line."""
    (tmp_path / "s.csv").write_text("x,y,label,step\n0.1,0.2,contact,1\n0.1,0.3,contact,99999999999999999999999\n")
    with pytest.raises(DatasetError, match="s.csv:3: step 99999999999999999999999 is out of range"):
        load_contacts_csv(tmp_path / "s.csv")
    (tmp_path / "n.csv").write_text("x,y,label,step\n0.1,0.2,contact,-1\n")
    with pytest.raises(DatasetError, match="n.csv:2: step -1 is out of range"):
        load_contacts_csv(tmp_path / "n.csv")


@pytest.mark.parametrize("header", ["FIELDS x y z x\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1",
                                    "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 0 1",
                                    "FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 -1 1"])
@pytest.mark.parametrize("binary", [False, True])
def test_pcd_headers_with_a_field_twice_or_no_count_are_refused_in_both_forms(tmp_path, header, binary):
    """Issue 33, item 10: `FIELDS x y z x` used the last x, COUNT 0 and -1 were accepted (ascii only)."""
    head = f"VERSION 0.7\n{header}\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA {'binary' if binary else 'ascii'}\n"
    body = np.zeros(4, "<f4").tobytes() if binary else b"0.1 0.2 0.3 0.9\n"
    (tmp_path / "c.pcd").write_bytes(head.encode() + body)
    with pytest.raises(DatasetError, match=r"c.pcd: PCD (FIELDS names \['x'\] more than once|COUNT and SIZE must be)"):
        load_point_cloud(tmp_path / "c.pcd")


def test_load_dataset_refuses_a_step_that_is_no_step_number():
    from torch_gpioius.io.datasets import load_dataset

    for bad in (2.5, -1, True, "3"):
        with pytest.raises(DatasetError, match="upto_step: must be a step number"):
            load_dataset("data/example_2d.gpioius", upto_step=bad)
    assert len(load_dataset("data/example_2d.gpioius", upto_step=2)) > 0


@pytest.mark.parametrize("ext", ["obj", "stl", "xyz"])
def test_a_garbage_file_is_named_as_not_a_mesh(tmp_path, ext):
    """Issue 33, item 15: the cause read "No module named 'charset_normalizer'"."""
    import charset_normalizer  # noqa: F401  (declared: trimesh decodes non-UTF-8 text files with it)

    from torch_gpioius.sim.meshes import load_mesh

    p = tmp_path / f"g.{ext}"
    p.write_bytes(np.random.default_rng(0).bytes(400) + b"\xff\xfe garbage")
    if ext == "xyz":
        with pytest.raises(DatasetError, match=r"g.xyz: not a readable XYZ point cloud"):
            load_point_cloud(p)
    else:
        with pytest.raises(ValueError, match=rf"g.{ext}\): not a (readable )?{ext.upper()} mesh"):
            load_mesh(p)


def _ball_files(tmp_path, shift=(0.0, 0.0, 0.0), contacts_scale=1.0):
    """A 10 cm ball's contacts (CSV, ``contacts_scale`` x metres) and its cover's cloud (PLY, metres, moved by
    ``shift``)."""
    import trimesh

    c = np.array([0.5, 0.0, 0.25])
    rng = np.random.default_rng(3)
    d = rng.normal(size=(20, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rows = ["x,y,z,label"] + [",".join(f"{v:.6f}" for v in p) + ",contact" for p in (d * 0.1 + c) * contacts_scale]
    (tmp_path / "touch.csv").write_text("\n".join(rows) + "\n")
    shell = trimesh.creation.icosphere(3, radius=0.108).vertices
    shell = shell[shell[:, 0] < 0.03] + c + np.asarray(shift)
    trimesh.PointCloud(shell).export(tmp_path / "cloud.ply")
    return tmp_path / "touch.csv", tmp_path / "cloud.ply", c


def test_a_cloud_that_does_not_belong_to_the_contacts_is_refused(tmp_path):
    """Issue 51, item 11: a cloud 1.5 m from the contacts (a frame mistake) fitted with a correlation of -0.76, and
    a millimetre CSV with a metre cloud under --units mm passed, each with exit 0 and no warning."""
    import warnings

    from torch_gpioius.io.importers import dataset_from_files

    csv_path, cloud, c = _ball_files(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ok = dataset_from_files(csv_path, cloud, settings=EstimatorOverrides(voxel=0.02),
                                camera_origin=c + [-1.0, 0.0, 0.3])
    assert (ok.task == 1).any()
    far_csv, far_cloud, _ = _ball_files(tmp_path, shift=(1.5, 0.0, 0.0))
    with pytest.raises(DatasetError, match=r"outside the cloud's box.*not in one frame or not in one unit"):
        dataset_from_files(far_csv, far_cloud, settings=EstimatorOverrides(voxel=0.02))
    mm_csv, m_cloud, _ = _ball_files(tmp_path, contacts_scale=1000.0)
    with pytest.raises(DatasetError, match="not in one frame or not in one unit"):
        dataset_from_files(mm_csv, m_cloud, units="mm", settings=EstimatorOverrides(voxel=0.02))


def test_a_camera_inside_the_cloud_is_warned_of(tmp_path):
    """Issue 51, item 11: a camera origin inside the object gave a correlation of -0.67, read out as a finding."""
    from torch_gpioius.io.importers import dataset_from_files

    csv_path, cloud, c = _ball_files(tmp_path)
    with pytest.warns(UserWarning, match="camera origin .* lies inside the cloud's convex hull"):
        dataset_from_files(csv_path, cloud, settings=EstimatorOverrides(voxel=0.02), camera_origin=c)


@pytest.mark.parametrize("row, match", [("0.5,0,0.2,-1e6", "below -20"), ("0.5,0,0.2,-1e308", "below -20"),
                                        ("0.5,0,0.2,inside", "positive number")])
def test_negative_labels_have_a_bound(tmp_path, row, match):
    """Issue 51, item 12: a CSV label of -1e6 fitted with exit 0 (K_t 2.6e10, correlation 0.0000 [-0.00, 0.00]);
    at -1e308 the message was "Eigenvalues did not converge"."""
    path = tmp_path / "c.csv"
    path.write_text("x,y,z,label,depth\n0.5,0,0.25,contact,\n" + row + ",\n")
    with pytest.raises(DatasetError, match=match):
        load_contacts_csv(path)
    path.write_text("x,y,z,label,depth\n0.5,0,0.25,inside,2\n")          # 2 m deep: refused too
    with pytest.raises(DatasetError, match="more than 1 m"):
        load_contacts_csv(path)
    path.write_text("x,y,z,label,depth\n0.5,0,0.25,inside,0.5\n0.5,0,0.2,-19.5,\n")   # 0.5 m and -19.5: kept
    assert load_contacts_csv(path)[1].tolist() == [-10.0, -19.5]


def test_a_model_refuses_labels_below_the_bound():
    import torch

    import torch_gpioius as tg

    x = torch.tensor([[0.0, 0.0], [0.1, 0.0], [0.2, 0.0]], dtype=torch.float64)
    with pytest.raises(ValueError, match=r"y: labels must be .*down to -20.*-1e\+300"):
        tg.GPIS(x, torch.tensor([0.0, 1.0, -1e300], dtype=torch.float64))
    assert tg.GPIS(x, torch.tensor([0.0, 1.0, -20.0], dtype=torch.float64)).train_targets.min() == -20.0


def test_an_npz_cloud_that_would_expand_without_bound_is_refused_before_it_expands(tmp_path, monkeypatch):
    """Issue 51, item 15: a 4.6 MB zip bomb in an NPZ cloud reached 4.9 GB before a MemoryError."""
    import io
    import zipfile

    import torch_gpioius.io.importers as importers

    bomb = tmp_path / "bomb.npz"
    np.savez_compressed(bomb, points=np.zeros((20_000, 3)))
    assert bomb.stat().st_size < 10_000                        # 480 kB of points in a few kB
    monkeypatch.setattr(importers, "MAX_CLOUD_BYTES", 100_000)
    with pytest.raises(DatasetError, match=r"bomb.npz: 'points' expands to .* more than"):
        load_point_cloud(bomb)
    monkeypatch.undo()
    assert load_point_cloud(bomb).shape == (20_000, 3)         # under the real bound it loads
    # a header that declares far more than the member holds (numpy would allocate the declared shape first)
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": (10**9, 3)})
    liar = tmp_path / "liar.npz"
    with zipfile.ZipFile(liar, "w") as zf:
        zf.writestr("points.npy", buf.getvalue() + np.zeros(6).tobytes())
    with pytest.raises(DatasetError, match=r"declares shape \(1000000000, 3\)"):
        load_point_cloud(liar)


def test_a_spreadsheets_csv_with_a_byte_order_mark_is_read(tmp_path):
    """Issue 51, item 25: a CSV saved as "CSV UTF-8" (with a byte-order mark) was refused: got ['\\ufeffx', ...]."""
    p = tmp_path / "c.csv"
    p.write_bytes("x,y,z,label\n0.5,0,0.25,contact\n0.5,0,0.35,free\n".encode("utf-8-sig"))
    x, y, _ = load_contacts_csv(p)
    assert x.shape == (2, 3) and y.tolist() == [0.0, 1.0]


def test_a_capture_that_sees_only_the_top_is_not_taken_for_another_frame(tmp_path):
    """The contacts lie inside the box of every capture together; a wrist camera's view of the top alone lies far
    from the contacts on the sides, and is no frame mistake."""
    from torch_gpioius.io.importers import dataset_from_files

    csv_path, cloud, c = _ball_files(tmp_path)
    import trimesh

    top = trimesh.creation.icosphere(3, radius=0.108).vertices
    top = top[top[:, 2] > 0.1] + c
    trimesh.PointCloud(top).export(tmp_path / "top.ply")
    ds = dataset_from_files(csv_path, [cloud, tmp_path / "top.ply"], settings=EstimatorOverrides(voxel=0.02),
                            camera_origin=[c + [-1.0, 0.0, 0.3], c + [0.0, 0.0, 0.5]])
    assert (ds.task == 1).sum() > 50


def _fitted(ds):
    """Final Chamfer [cm] of a dataset's inner estimate against the 6 cm sphere of tests.userfiles."""
    from tests.userfiles import CENTRE
    from torch_gpioius.geometry.surfaces import zero_level_mesh

    model = ds.to_model().fit()
    mesh = zero_level_mesh(model, [CENTRE - 0.12, CENTRE + 0.12], 0.01)
    r = np.linalg.norm(np.asarray(mesh.vertices) - CENTRE, axis=1)
    return float(np.mean(np.abs(r - 0.06)) * 100), model


def test_camera_origins_their_captures_face_away_from_are_named(tmp_path):
    """Issue 60, item 5: two origins in the wrong order, or in metres beside millimetre files, took the correlation
    from 1.00 to 0.09 without a word. A camera sees the near side of a body: the capture whose points face away from
    its origin is named."""
    from tests.userfiles import EYES, sphere_files

    csv, clouds = sphere_files(tmp_path, contacts=20, cover=800)
    with warnings.catch_warnings():
        warnings.simplefilter("error")                          # the right order: not a word
        dataset_from_files(csv, clouds, camera_origin=list(EYES))
    with pytest.warns(UserWarning) as seen:
        dataset_from_files(csv, clouds, camera_origin=list(EYES[::-1]))
    said = [str(w.message) for w in seen if "face its camera origin" in str(w.message)]
    assert len(said) == 2 and said[0].startswith("capture 1 of 2") and said[1].startswith("capture 2 of 2")
    # millimetre files beside origins typed in metres (the origin lands by the base frame's origin)
    mm = tmp_path / "mm"
    mm.mkdir()
    rows = (tmp_path / "contacts.csv").read_text().splitlines()
    (mm / "c.csv").write_text("\n".join([rows[0]] + [",".join([f"{float(v) * 1000:.3f}" for v in r.split(",")[:3]]
                                                              + r.split(",")[3:]) for r in rows[1:]]) + "\n")
    for k, cloud in enumerate(clouds):
        trimesh.PointCloud(np.asarray(trimesh.load(cloud).vertices) * 1000).export(mm / f"{k}.ply")
    with pytest.warns(UserWarning, match=r"capture 1 of 2 .* only \d+ % of its points face its camera origin"):
        dataset_from_files(mm / "c.csv", [mm / "0.ply", mm / "1.ply"], units="mm", camera_origin=list(EYES))


def test_normals_that_point_into_the_body_are_turned_round_and_said(tmp_path):
    """Issue 60, item 6: normals (or forces) of the wrong sign put every inside point outside the body: contacts alone
    1.76 cm against 0.27 cm, silently. The file's own free rows, the seen surface and the contacts' middle say which
    way is out; the estimate from inward normals is then the estimate from outward ones."""
    from tests.userfiles import EYES, sphere_files

    right, _ = sphere_files(tmp_path, contacts=30, cover=600)
    wrong, clouds = sphere_files(tmp_path, contacts=30, cover=600, normal_sign=-1.0, name="inward.csv")
    good = dataset_from_files(right, settings="default")
    with pytest.warns(UserWarning, match=r"point into the body by the data's own account \(inward by free rows 15 of "
                                         r"15, the contacts' middle 30 of 30\): turned round"):
        turned = dataset_from_files(wrong, settings="default")
    assert np.array_equal(turned.x, good.x) and np.array_equal(turned.y, good.y)
    with pytest.warns(UserWarning, match="the seen surface 30 of 30"):
        with_clouds = dataset_from_files(wrong, clouds, camera_origin=list(EYES))
    assert int((with_clouds.y[with_clouds.task == 0] < 0).sum()) == 30      # every inside point kept
    import torch_gpioius.io.importers as importers

    unturned = importers._outward
    importers._outward = lambda csv, x, y, normal, seen: normal        # the releases that took the sign as given
    try:
        silent = dataset_from_files(wrong, settings="default")
    finally:
        importers._outward = unturned
    right_cm, wrong_cm = _fitted(turned)[0], _fitted(silent)[0]
    assert right_cm < 0.7 and wrong_cm > right_cm + 0.3, (right_cm, wrong_cm)


def test_inside_points_that_come_out_of_a_thin_body_are_dropped_and_said(tmp_path):
    """Issue 60, item 6: with clouds, 46 of 60 inside points were dropped without a word. On a ball of 8 mm radius
    the inside points 2 cm behind each contact come out on its far side, where the other observations show free
    space: dropped, and the warning names the likelier cause (the normals point out by the data's vote) and the
    depth. On a 6 cm ball none is dropped and nothing is said."""
    import warnings

    from tests.userfiles import EYES, sphere_files

    thin, clouds = sphere_files(tmp_path, contacts=30, cover=600, radius=0.008, name="thin.csv")
    with pytest.warns(UserWarning, match=r"of 30 inside points behind the contacts .* were dropped\. The contacts' "
                                         r"directions point out of the body .* thinner than the inside points' depth "
                                         r"\(2 cm\)"):
        data = dataset_from_files(thin, clouds, camera_origin=list(EYES))
    assert int((data.y[data.task == 0] < 0).sum()) < 23
    ball, clouds = sphere_files(tmp_path, contacts=30, cover=600, name="ball.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        data = dataset_from_files(ball, clouds, camera_origin=list(EYES))
    assert int((data.y[data.task == 0] < 0).sum()) == 30


def test_repeated_rows_count_once_and_stray_rows_separators_and_underscores_are_named(tmp_path):
    """Issue 60, items 7 and 17: a CSV whose rows repeat counted as three times the evidence; a single row of 1e300
    was blamed on millimetres without its line; ';' or tab separated files got no hint (now read); `0.5_0` was read
    as 0.5."""
    from tests.userfiles import sphere_files

    once, _ = sphere_files(tmp_path, contacts=10, cover=100, name="once.csv")
    thrice, _ = sphere_files(tmp_path, contacts=10, cover=100, repeat=3, name="thrice.csv")
    with pytest.warns(UserWarning, match=r"50 of 75 rows repeat an earlier row .* merged, each observation counted"):
        x3, y3, s3, n3 = read_contacts_csv(thrice)
    x1, y1, s1, n1 = read_contacts_csv(once)
    assert np.array_equal(x1, x3) and np.array_equal(y1, y3) and np.array_equal(n1, n3, equal_nan=True)
    text = once.read_text().splitlines()
    for sep in (";", "\t"):
        (tmp_path / "sep.csv").write_text("\n".join(r.replace(",", sep) for r in text) + "\n")
        xs, ys, _, ns = read_contacts_csv(tmp_path / "sep.csv")
        assert np.array_equal(xs, x1) and np.array_equal(ns, n1, equal_nan=True)
    stray = text[:4] + ["1e300,0,0.2,contact,,,"] + text[4:]
    (tmp_path / "stray.csv").write_text("\n".join(stray) + "\n")
    with pytest.raises(DatasetError, match=r"stray.csv: line 5 \(1e\+300, 0, 0.2\) lies far from every other point"):
        read_contacts_csv(tmp_path / "stray.csv")
    for bad, match in (("0.5_0,0,0.2,contact,,,", r"coordinates \['0.5_0', '0', '0.2'\] are not numbers"),
                       ("0.5,0,0.2,contact,0_1,0,1", r"nx, ny, nz \['0_1', '0', '1'\] are not numbers")):
        (tmp_path / "bad.csv").write_text(text[0] + "\n" + bad + "\n")
        with pytest.raises(DatasetError, match=match):
            read_contacts_csv(tmp_path / "bad.csv")
    (tmp_path / "euro.csv").write_text("x;y;z;label\n0,5;0;0,2;contact\n")
    with pytest.raises(DatasetError, match="decimal commas"):
        read_contacts_csv(tmp_path / "euro.csv")


def test_free_rows_alone_and_a_mesh_given_as_a_cloud_are_said_for_what_they_are(tmp_path):
    """Issue 60, items 17 and 18: a file of free rows alone was refused as "the contacts lie 7 cm outside"; a PLY
    mesh given as a cloud had its vertices used without a word."""
    from tests.userfiles import EYES, sphere_files

    csv, clouds = sphere_files(tmp_path, contacts=10, cover=400)
    free = [r for r in csv.read_text().splitlines() if "free" in r or r.startswith("x,")]
    (tmp_path / "free.csv").write_text("\n".join(free) + "\n")
    with pytest.warns(UserWarning, match="no contact rows"):
        ds = dataset_from_files(tmp_path / "free.csv", clouds, camera_origin=list(EYES))
    assert int((ds.task == 0).sum()) == 15
    trimesh.creation.icosphere(2, 0.07).apply_translation([0.5, 0.0, 0.2]).export(tmp_path / "mesh.ply")
    with pytest.warns(UserWarning, match=r"mesh.ply: holds a mesh \(320 faces\), not a point cloud: its 162 vertices"):
        assert len(load_point_cloud(tmp_path / "mesh.ply")) == 162


def _box_files(folder, error: str, *, top_only: bool = False, table: bool = False, seed: int = 0):
    """A 10 x 8 x 12 cm box under a cover 8 mm off, its contacts (with normals) in a CSV and three captures of the
    cover by cameras whose calibration is off by ``error``; returns the CSV, the clouds, their origins and the
    cover's mesh. ``top_only``: 40 contacts on the top face (else 120 on every face but the bottom); ``table``: the
    captures see the table the cover stands on too (at ``TABLE_Z``, in the clouds as a camera gives them)."""
    from torch_gpioius.sensors.simulated.camera import SimulatedDepthCamera
    from torch_gpioius.sensors.pointcloud import PinholeCamera, look_at

    centre = np.array([0.5, 0.0, 0.2])
    inner = trimesh.creation.box((0.10, 0.08, 0.12))
    inner.apply_translation(centre)
    outer = trimesh.creation.box((0.116, 0.096, 0.136))
    outer.apply_translation(centre)
    points, face = trimesh.sample.sample_surface(inner, 400, seed=1)
    keep = inner.face_normals[face][:, 2] > (0.5 if top_only else -0.5)
    count = 40 if top_only else 120
    rows = [f"{x:.6f},{y:.6f},{z:.6f},contact,{a:.4f},{b:.4f},{c:.4f}"
            for (x, y, z), (a, b, c) in zip(points[keep][:count], inner.face_normals[face][keep][:count])]
    csv = folder / "touch.csv"
    csv.write_text("x,y,z,label,nx,ny,nz\n" + "\n".join(rows) + "\n")
    eyes = [centre + [-0.6, -0.8, 0.5], centre + [-0.6, 0.8, 0.5], centre + [-0.4, 0.0, 0.8]]
    clouds = []
    for k, eye in enumerate(eyes):
        cam = SimulatedDepthCamera(outer, PinholeCamera.kinect_v2(0.5), look_at(eye, centre), noise_a=0.0015,
                                   noise_b=0.0015, seed=[seed, k], error=error, support=TABLE_Z if table else None)
        shot = cam.capture()
        clouds.append(folder / f"view{k}.ply")
        trimesh.PointCloud(np.r_[shot.points, shot.support] if table else shot.points).export(clouds[-1])
    return csv, clouds, eyes, outer


#: The height of the table under :func:`_box_files`' box [m] (its cover's bottom).
TABLE_Z = 0.2 - 0.068


def test_captures_of_a_miscalibrated_camera_are_corrected_from_the_contacts_and_said(tmp_path):
    """Issue 63, item 2: `camera_bound` moves each capture onto the contacts (the seen cover's points fall from
    6-12 mm off the true cover to about the depth noise), records each correction, and warns of the large ones by
    file; without it the captures are used as given."""
    csv, clouds, eyes, outer = _box_files(tmp_path, "6mm,1deg")
    with pytest.warns(UserWarning, match="calibration is off by millimetres does this too"):
        every = EstimatorOverrides(voxel=0)
        as_given = dataset_from_files(csv, clouds, camera_origin=eyes, settings=every)   # the inside points' hint
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fixed = dataset_from_files(csv, clouds, camera_origin=eyes, settings=every, camera_bound="12mm,2deg")
    assert "camera_corrections" not in as_given.meta
    record = fixed.meta["camera_corrections"]
    assert len(record["captures"]) == 3 and record["misfit_after_mm"] < record["misfit_before_mm"]
    assert all(c["contacts"] >= 20 for c in record["captures"])

    def off_the_cover(ds):
        seen = ds.x[(ds.task == 1) & (ds.y == 0)]
        return float(np.median(np.abs(trimesh.proximity.signed_distance(outer, seen[::10]))))

    assert off_the_cover(as_given) > 0.005 and off_the_cover(fixed) < 0.0025
    said = [str(w.message) for w in caught if "check the camera's calibration" in str(w.message)]
    assert said and all(any(str(c) in line for c in clouds) for line in said)
    for bad, match in (("6mm", "give both a translation and a rotation"), ("6", "not a size with a unit")):
        with pytest.raises(DatasetError, match=match):
            dataset_from_files(csv, clouds, camera_origin=eyes, camera_bound=bad)
    with pytest.raises(DatasetError, match="give each cloud its camera origin"):
        dataset_from_files(csv, clouds, camera_bound="6mm,1deg")


def test_a_users_files_under_a_wide_cover_take_the_gap_rules_their_settings_name(tmp_path):
    """A 6 cm ball under a cover 4 cm off it, seen from both sides. Without the gap settings the camera's inside
    points are retracted (nothing below the seen cover is left, the outer mean stays 1). The default takes the one gap,
    since the touches agree on it here (``cover_even``), as the ungated setting does: it keeps the inside points and
    continues them down to the gap, and the dataset records the mean (``cover_offset``). The gap field
    (``cover_gap_field``) is recorded as the field, which the model built from the dataset takes and reads as about
    4 cm at the cover."""
    import torch_gpioius as tg
    from torch_gpioius.io.importers import dataset_from_files

    from tests.userfiles import CENTRE, EYES, sphere_files

    csv_path, clouds = sphere_files(tmp_path, contacts=40, gap=0.04)
    base = tg.EstimatorSettings.default()
    origins = [list(e) for e in EYES]
    off = {"cover_offset": False, "vision_inside_deep": False}
    plain = dataset_from_files(csv_path, clouds, settings=base.replace(labels=off), camera_origin=origins)
    assert not ((plain.task == 1) & (plain.y < 0)).any() and "outer_mean" not in plain.meta
    assert plain.to_model().outer_mean == 1.0
    first = base.labels.inside_label(base.labels.vision_inside)
    sets = {"default": base, "ungated": base.replace(labels={"cover_even": None})}
    for name, settings in sets.items():
        one = dataset_from_files(csv_path, clouds, settings=settings, camera_origin=origins)
        gap = one.meta["cover_gap"]
        assert 0.03 < gap <= 0.04, name
        assert ((one.task == 1) & (one.y < first - 1e-9)).any(), name           # continued below the first
        assert one.meta["outer_mean"] == pytest.approx(1 - gap / base.labels.ramp, abs=1e-12)
        assert one.to_model().outer_mean == one.meta["outer_mean"]
    field = dataset_from_files(csv_path, clouds, settings=base.replace(labels={"cover_gap_field": True}),
                               camera_origin=origins)
    model = field.to_model()
    assert model.outer_field is not None and "outer_mean" not in field.meta
    seen = field.x[(field.task == 1) & (field.y == 0)]
    top = seen[seen[:, 2] > CENTRE[2] + 0.05]                                 # where the contacts are
    assert 0.025 < float(model.outer_field.gap(top).median()) < 0.045


def test_a_users_captures_held_to_the_table_they_see_as_well(tmp_path):
    """The box's three captures with the table around it (uncropped, as a camera gives them) and the table's height
    known (``table``, ``gpioius fit --table``): each capture's table points are found (within the bound's band of the
    height, away from the box's foot), held to the plane with the contacts, and taken out of the labelled captures;
    with only the contacts on the box's top face the seen cover's points land closer to the true cover than without
    the table. A table without a bound, or not a number, is refused by name."""
    csv, clouds, eyes, outer = _box_files(tmp_path, "6mm,1deg", top_only=True, table=True, seed=1)
    centre, table = np.array([0.5, 0.0, 0.2]), TABLE_Z

    def off_the_cover(ds):
        seen = ds.x[(ds.task == 1) & (ds.y == 0)]
        return float(np.median(np.abs(trimesh.proximity.signed_distance(outer, seen[::10]))))

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        every = EstimatorOverrides(voxel=0)
        contacts_only = dataset_from_files(csv, clouds, camera_origin=eyes, settings=every, camera_bound="12mm,2deg")
        held = dataset_from_files(csv, clouds, camera_origin=eyes, settings=every, camera_bound="12mm,2deg",
                                  table=table)
    assert all(c["support"] >= 100 for c in held.meta["camera_corrections"]["captures"])
    def low(ds):                                   # seen points at the table's height, beyond the box's foot
        seen = ds.x[(ds.task == 1) & (ds.y == 0)]
        beyond = (np.abs(seen[:, :2] - centre[:2]) > [0.058 + 0.03, 0.048 + 0.03]).any(axis=1)
        return int(((seen[:, 2] < table + 0.01) & beyond).sum())

    assert low(contacts_only) > 1000 and low(held) < 0.02 * low(contacts_only)    # the table left the captures
    assert off_the_cover(held) < off_the_cover(contacts_only), (off_the_cover(held), off_the_cover(contacts_only))
    with pytest.raises(DatasetError, match="table"):
        dataset_from_files(csv, clouds, camera_origin=eyes, camera_bound="12mm,2deg", table="low")
