"""Exports of the estimated surfaces: what is written is the model's zero level set, with its variance."""

import numpy as np
import pytest
import torch
import trimesh

import torch_gpioius as tg
from torch_gpioius.cli import main
from torch_gpioius.io.datasets import Dataset, save_dataset
from torch_gpioius.io.export import export_run
from torch_gpioius.io.runs import load_run


@pytest.fixture(scope="module")
def log_2d(tmp_path_factory):
    path = tmp_path_factory.mktemp("runs") / "A.gpioius"
    tg.explore(tg.sim.paper_objects_2d()["A"], mode="visual-tactile", max_steps=5, log=path, progress=False)
    return path


@pytest.fixture(scope="module")
def dataset_3d(tmp_path_factory):
    rng = np.random.default_rng(1)
    d = rng.standard_normal((120, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    x = np.concatenate([0.06 * d[:30], 0.12 * d[30:40], 0.08 * d[40:100], 0.13 * d[100:]])
    y = np.concatenate([np.zeros(30), np.ones(10), np.zeros(60), np.ones(20)])
    task = np.concatenate([np.zeros(40), np.ones(80)]).astype(np.int64)
    step = np.concatenate([np.arange(30) + 1, np.arange(10) * 3 + 1, np.zeros(80)]).astype(np.int64)
    path = tmp_path_factory.mktemp("data") / "ball.gpioius"
    save_dataset(Dataset(x, y, task, step, meta={"theta": 0.1, "noise": 0.006}), path)
    return path


def test_3d_mesh_is_the_zero_level_set_with_its_variance(dataset_3d, tmp_path):
    info = export_run(dataset_3d, tmp_path / "inner.ply", outer=tmp_path / "outer.obj", resolution=0.01)
    assert info["step"] == 30 and info["faces"] > 100
    model = load_run(dataset_3d).model_at(30)
    mesh = trimesh.load(tmp_path / "inner.ply", process=False)
    with torch.no_grad():
        mean, var = model.predict(torch.tensor(np.asarray(mesh.vertices, dtype=np.float64)), task=0)
    # vertices come from marching cubes on a 1 cm grid (linear interpolation of mu along cell edges) and are
    # stored as float32: |mu| at them stays well below the change of mu over one cell (~0.1 here)
    assert float(mean.abs().max()) < 0.02
    stored = mesh.metadata["_ply_raw"]["vertex"]["data"]["variance"]
    np.testing.assert_allclose(stored, var.numpy(), rtol=1e-5, atol=1e-9)
    outer = trimesh.load(tmp_path / "outer.obj", process=False)
    r_out = np.linalg.norm(outer.vertices, axis=1)
    assert abs(np.median(r_out) - 0.08) < 0.01        # the outer estimate sits on the seen 8 cm sphere


def test_2d_curves_at_a_step_and_every_format(log_2d, tmp_path):
    run = load_run(log_2d)
    for name in ("a.svg", "a.dxf", "a.ply", "a.obj"):
        info = export_run(log_2d, tmp_path / name, step=2)
        assert info["step"] == 2 and (tmp_path / name).stat().st_size > 0
    ply = (tmp_path / "a.ply").read_text().splitlines()
    n = int(ply[2].split()[-1])
    pts = np.array([[float(v) for v in line.split()[:2]] for line in ply[ply.index("end_header") + 1:][:n]])
    with torch.no_grad():
        mean, _ = run.model_at(2).predict(torch.tensor(pts), task=0)
    assert float(mean.abs().max()) < 0.01        # contour vertices: mu = 0 up to the grid's interpolation


def test_bad_requests_are_one_line_and_leave_nothing(log_2d, dataset_3d, tmp_path, capsys):
    cases = [
        (["export", str(log_2d)], "nothing to write"),
        (["export", str(log_2d), "--mesh", str(tmp_path / "x.stl")], "a 2-D estimate is a set of closed curves"),
        (["export", str(dataset_3d), "--mesh", str(tmp_path / "x.svg")], "a 3-D estimate is a mesh"),
        (["export", str(log_2d), "--mesh", str(tmp_path / "x.svg"), "--step", "-3"], "is outside the run's steps 0-"),
        # issue 35, item 7: past the end it exported the last step silently; both ends are refused alike now
        (["export", str(log_2d), "--mesh", str(tmp_path / "x.svg"), "--step", "40"], "is outside the run's steps 0-"),
        (["export", str(tmp_path / "missing.gpioius"), "--mesh", str(tmp_path / "x.svg")], "missing.gpioius"),
    ]
    for argv, expected in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("gpioius: error:") and expected in err and "\n" not in err
    assert not any(tmp_path.glob("x.*"))
    tactile = tmp_path / "t.gpioius"
    tg.explore(tg.sim.paper_objects_2d()["A"], mode="tactile", max_steps=3, log=tactile, progress=False)
    with pytest.raises(ValueError, match="no outer model"):
        export_run(tactile, tmp_path / "i.svg", outer=tmp_path / "o.svg")
    assert not (tmp_path / "i.svg").exists()


def test_one_rule_for_existing_files_links_and_two_outputs_in_one_file(log_2d, dataset_3d, tmp_path, capsys):
    """Nothing that exists is replaced without --force; with it a link is replaced, never followed; two outputs
    may not name one file (``--mesh X --outer X`` lost the inner estimate)."""
    target = tmp_path / "precious.ply"
    target.write_text("someone's mesh\n")
    link = tmp_path / "inner.ply"
    link.symlink_to(target)
    assert main(["export", str(dataset_3d), "--mesh", str(link)]) == 2
    assert "inner.ply: exists; pass --force" in capsys.readouterr().err
    assert main(["export", str(dataset_3d), "--mesh", str(link), "--force"]) == 0
    assert target.read_text() == "someone's mesh\n"                 # the link's target is untouched
    assert not link.is_symlink() and trimesh.load(link).vertices.shape[1] == 3
    same = tmp_path / "both.ply"
    assert main(["export", str(dataset_3d), "--mesh", str(same), "--outer", str(same)]) == 2
    assert "--outer and --mesh name the same file" in capsys.readouterr().err and not same.exists()
    assert main(["export", str(dataset_3d), "--mesh", str(tmp_path / "i.ply"), "--resolution", "0"]) == 2
    assert "resolution: must be positive" in capsys.readouterr().err          # 0 used to mean the default
    assert main(["export", str(log_2d), "--mcap", str(tmp_path / "nodir" / "b.mcap")]) == 2
    assert f"the folder {tmp_path / 'nodir'} does not exist" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["out.SVG", "out.DXF", "out.Obj"])
def test_upper_case_endings_write_the_format(log_2d, tmp_path, name):
    """``--mesh out.SVG`` raised a KeyError inside trimesh; the ending's case does not matter."""
    export_run(log_2d, tmp_path / name)
    text = (tmp_path / name).read_text()
    assert {"SVG": "<svg", "DXF": "SECTION", "Obj": "v "}[name.split(".")[1]] in text
