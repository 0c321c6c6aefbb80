"""The command line: help texts, the one rule for existing outputs, what `fit` and `replay` report."""

import re

import numpy as np
import torch
import pytest

from torch_gpioius.cli import build_parser, main
from torch_gpioius.models.estimator import EstimatorSettings
from torch_gpioius.models.overrides import EstimatorOverrides

ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "data" / "example_2d.gpioius"


def _subparsers():
    parser = build_parser()
    action = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return action.choices


def test_every_option_shows_its_default_once():
    for name, sub in _subparsers().items():
        text = sub.format_help()
        assert "(default: None)" not in text, name
        for entry in re.split(r"\n  (?=-)", text):                  # one option's help per entry
            assert entry.count("(default") <= 1, (name, entry)


def test_fit_prints_the_interval_and_what_it_means(capsys):
    import torch_gpioius as tg

    assert main(["fit", str(EXAMPLE)]) == 0
    out = capsys.readouterr().out
    m = re.search(r"correlation = (-?[\d.]+), 95 % profile-likelihood interval \[(-?[\d.]+), (-?[\d.]+)\]", out)
    assert m, out
    model = tg.load_dataset(EXAMPLE).to_model().fit()
    lo, hi = model.similarity_interval(0.95)
    assert (float(m[2]), float(m[3])) == (round(lo, 2), round(hi, 2))
    assert float(m[2]) <= float(m[1]) <= float(m[3])
    assert "the data cannot tell" in out or "predicts the inner one" in out


def test_fit_learns_the_length_and_noise_when_asked_and_saves_them(tmp_path, capsys):
    """`gpioius fit --learn all`: the checkpoint holds the learned values (the model's own parameters), fit.json and
    the printout say them, and the full data's likelihood did not fall."""
    import json

    import torch_gpioius as tg
    from torch_gpioius.io.checkpoints import load_checkpoint

    assert main(["fit", str(EXAMPLE), "--learn", "all", "--out", str(tmp_path / "fit")]) == 0
    out = capsys.readouterr().out
    assert re.search(r"learned \(all, \d+ points, \d+ evaluations\): length = [\d.e-]+ m, sigma\^2 = ", out), out
    info = json.loads((tmp_path / "fit" / "fit.json").read_text())
    r = info["learned"]
    model = load_checkpoint(tmp_path / "fit" / "model.pt")
    assert r["kept"] and r["length"] != 0.1
    assert model.kernel.length == pytest.approx(r["length"], rel=1e-12)
    assert model.noise == pytest.approx(r["noise"], rel=1e-9) and info["mll"] >= r["mll_before"]
    fixed = tg.load_dataset(EXAMPLE).to_model().fit()
    assert info["mll"] >= float(fixed.log_marginal_likelihood()) - 1e-9 * abs(info["mll"])
    with pytest.raises(SystemExit):                  # argparse refuses an unknown choice, naming the choices
        main(["fit", str(EXAMPLE), "--learn", "nothing"])
    assert "invalid choice: 'nothing'" in capsys.readouterr().err


def test_commands_never_write_into_someone_elses_folder(tmp_path, capsys):
    theirs = tmp_path / "results"
    theirs.mkdir()
    (theirs / "summary.md").write_text("their table\n")
    for argv in (["simulate", "--smoke", "--object", "A", "--out", str(theirs)],
                 ["fit", str(EXAMPLE), "--out", str(theirs)], ["replay", str(EXAMPLE), "--out", str(theirs)],
                 ["study", "--smoke", "--objects", "A", "--seeds", "1", "--out", str(theirs)]):
        assert main(argv) == 2, argv
        assert "was not written by `gpioius" in capsys.readouterr().err
    assert sorted(p.name for p in theirs.iterdir()) == ["summary.md"]
    assert (theirs / "summary.md").read_text() == "their table\n"
    # a folder a command wrote itself it may write again (make demo twice)
    mine = tmp_path / "fit"
    assert main(["fit", str(EXAMPLE), "--out", str(mine)]) == 0
    assert main(["fit", str(EXAMPLE), "--out", str(mine)]) == 0
    assert main(["replay", str(EXAMPLE), "--out", str(mine), "--quiet"]) == 2      # but not another command's
    capsys.readouterr()


def test_replay_labels_what_is_missing_by_its_cause(tmp_path, monkeypatch):
    """A visual-tactile 3-D dataset was labelled "tactile log" wherever a panel was empty."""
    from matplotlib.figure import Figure

    from torch_gpioius.io.datasets import Dataset, save_dataset
    from torch_gpioius.fitting import replay_log

    rng = np.random.default_rng(2)
    d = rng.standard_normal((90, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    x = np.concatenate([0.06 * d[:20], 0.12 * d[20:30], 0.08 * d[30:]])
    y = np.concatenate([np.zeros(20), np.ones(10), np.zeros(60)])
    task = np.concatenate([np.zeros(30), np.ones(60)]).astype(np.int64)
    step = np.concatenate([np.arange(20) + 1, np.arange(10) + 1, np.zeros(60)]).astype(np.int64)
    data = save_dataset(Dataset(x, y, task, step, meta={"theta": 0.1, "noise": 0.006}), tmp_path / "vt.gpioius")
    texts = []
    real = Figure.savefig

    def grab(fig, *args, **kwargs):
        texts.extend(t.get_text() for ax in fig.axes for t in ax.texts)
        return real(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", grab)
    rows = replay_log(data, tmp_path / "replay", every=5, progress=False)
    assert all(np.isfinite(r["correlation"]) for r in rows)
    assert np.isfinite(rows[-1]["uncertainty"])                     # 3-D uncertainty is computed too
    joined = " ".join(texts)
    assert "tactile" not in joined and "no known true shape" in joined


def test_study_defaults_to_the_worlds_own_objects(monkeypatch, tmp_path):
    """`gpioius study --world mujoco` failed: the default --objects were the 2-D A-D."""
    import torch_gpioius.studies.study as sweep

    seen = {}

    def fake(**kw):
        seen.update(kw)
        raise ValueError("stop here")

    monkeypatch.setattr(sweep, "run_sweep", fake)
    assert main(["study", "--world", "mujoco", "--smoke", "--out", str(tmp_path / "s")]) == 2
    assert seen["objects"] is None and seen["world"] == "mujoco"
    assert sweep.DEFAULT_OBJECTS["mujoco"] == ("E", "F", "G", "H")


@pytest.fixture
def seen(monkeypatch) -> dict:
    """The keyword arguments the study and the 3-D simulation would have been called with (neither runs)."""
    import torch_gpioius.studies.simulate3d as study3d
    import torch_gpioius.studies.study as sweep

    calls = {}

    def fake(*args, **kw):
        calls.update(kw)
        raise ValueError("stop here")

    monkeypatch.setattr(sweep, "run_sweep", fake)
    monkeypatch.setattr(study3d, "run_study_3d", fake)
    return calls


def test_voxel_reaches_the_study_and_the_3d_simulation_and_bad_values_are_refused(seen, tmp_path, capsys):
    assert main(["study", "--world", "forcefield", "--voxel", "0.01", "--out", str(tmp_path / "s")]) == 2
    assert seen["estimator"].voxel == 0.01
    assert main(["simulate3d", "--voxel", "0", "--touch", "patch", "--out", str(tmp_path / "t")]) == 2
    assert seen["estimator"].voxel == 0.0 and seen["touch"] == "patch"
    assert main(["simulate3d", "--noise", "0.05", "--estimator", "labels.ray_smoothing=none",
                 "--out", str(tmp_path / "t2")]) == 2                 # every estimator flag, as study's
    assert seen["estimator"] == EstimatorOverrides(noise=0.05, labels={"ray_smoothing": None})
    for bad in ("abc", "-0.01", "nan", "3"):
        with pytest.raises(SystemExit):
            main(["study", "--voxel", bad, "--out", str(tmp_path / "u")])
        assert "voxel" in capsys.readouterr().err
    assert not (tmp_path / "u").exists()


def test_device_and_outer_tol_reach_the_study_and_the_3d_simulation(seen, tmp_path, capsys):
    assert main(["study", "--device", "cpu", "--outer-tol", "1e-3", "--out", str(tmp_path / "s")]) == 2
    assert seen["device"] == "cpu" and seen["outer_tol"] == 1e-3
    assert main(["simulate3d", "--device", "cpu", "--outer-tol", "1e-3", "--out", str(tmp_path / "t")]) == 2
    assert seen["device"] == "cpu" and seen["outer_tol"] == 1e-3
    with pytest.raises(SystemExit, match="outer-tol"):         # patch runs have no truncated basis
        main(["simulate3d", "--touch", "patch", "--outer-tol", "1e-3", "--out", str(tmp_path / "u")])
    for option, bad in (("--device", "gpu"), ("--outer-tol", "-1"), ("--outer-tol", "nan")):
        with pytest.raises(SystemExit):
            main(["simulate3d", option, bad, "--out", str(tmp_path / "v")])
        assert option.strip("-").replace("-", "_") in capsys.readouterr().err.replace("-", "_")
    assert not (tmp_path / "u").exists() and not (tmp_path / "v").exists()


def test_policy_with_voxel():
    from torch_gpioius.exploration.observations import ObservationPolicy

    policy = ObservationPolicy(voxel=0.05, crop_margin=0.15)
    assert policy.with_voxel(0.01) == ObservationPolicy(voxel=0.01, crop_margin=0.15)
    assert policy.with_voxel(0).voxel is None                     # every camera point
    with pytest.raises(ValueError, match="voxel"):
        policy.with_voxel(-1.0)


@pytest.fixture
def fake_2d_study(monkeypatch):
    """run_study replaced by one that writes what the real one writes for its objects (in a second)."""
    import torch_gpioius.studies.simulate as study2d

    def fake(objects, out, **kw):
        from pathlib import Path

        out = Path(out)
        for o in objects:
            (out / f"fig4_{o}.png").write_bytes(b"png")
        (out / "summary.md").write_text("objects " + ",".join(objects) + "\n")
        return {"seconds": 0.0}

    monkeypatch.setattr(study2d, "run_study", fake)


def test_simulate_refuses_a_folder_of_another_objects_run(tmp_path, capsys, fake_2d_study):
    """Issue 33, item 3: `--object B` into A's folder left A's figures beside B's table, and both exited 0."""
    out = tmp_path / "sim"
    assert main(["simulate", "--object", "A", "--out", str(out)]) == 0
    assert main(["simulate", "--object", "A", "--out", str(out)]) == 0          # the same run again: allowed
    before = sorted(p.name for p in out.iterdir())
    assert main(["simulate", "--object", "B", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "holds the output of another run (objects='A')" in err and "objects='B'" in err
    assert sorted(p.name for p in out.iterdir()) == before
    assert (out / "summary.md").read_text() == "objects A\n"
    assert main(["simulate", "--object", "B", "--out", str(out), "--force"]) == 0   # asked for


def test_simulate_folders_written_before_the_objects_were_recorded_are_reused(tmp_path, fake_2d_study):
    import json

    out = tmp_path / "old"
    out.mkdir()
    (out / ".gpioius-output.json").write_text(json.dumps({"command": "simulate", "version": "0.9"}))
    (out / "summary.md").write_text("old\n")
    assert main(["simulate", "--object", "all", "--out", str(out)]) == 0
    assert json.loads((out / ".gpioius-output.json").read_text())["objects"] == "A,B,C,D"


@pytest.mark.parametrize("command", ["simulate", "simulate3d"])
def test_simulations_lock_their_folder(tmp_path, capsys, fake_2d_study, seen, command):
    """Two simulations into one folder at once both exited 0, their files mixed."""
    from torch_gpioius.io.outputs import FolderLock

    out = tmp_path / "sim"
    out.mkdir()
    with FolderLock(out, f"gpioius {command}"):
        assert main([command, "--out", str(out)]) == 2
    assert f"another gpioius {command} (pid" in capsys.readouterr().err
    assert not (out / "summary.md").exists() and not seen          # nothing ran


def test_lengths_in_the_wrong_units_are_refused(tmp_path, capsys, seen):
    """Issue 33, item 6: `--max-travel 150` ran for 86 s until the step cap."""
    from torch_gpioius.exploration.stopping import TravelBudget

    for command in ("simulate3d", "study"):
        with pytest.raises(SystemExit):
            main([command, "--world", "forcefield", "--max-travel", "150", "--out", str(tmp_path / "x")] if command ==
                 "study" else [command, "--max-travel", "150", "--out", str(tmp_path / "x")])
        assert "--max-travel: 150 m is above 20 m; lengths are in metres" in capsys.readouterr().err
    assert not seen
    with pytest.raises(ValueError, match="max_travel: 150 m is above 20 m"):
        TravelBudget(150.0)


def test_fit_on_a_dataset_in_millimetres_is_refused_by_its_units(tmp_path, capsys):
    """`gpioius fit` printed correlation 1.0 on data in mm; with --out it blamed the grid resolution."""
    from torch_gpioius.io.datasets import Dataset, save_dataset

    rng = np.random.default_rng(0)
    x = rng.uniform(-150, 150, size=(40, 2))
    bad = tmp_path / "mm.gpioius"
    # written as the old writer did (no check), so that the reader's check is the one tested
    import torch_gpioius.io.datasets as datasets

    real = datasets.check_metres
    datasets.check_metres = lambda *a, **k: None
    try:
        save_dataset(Dataset(x, (np.arange(40) % 2).astype(float), (np.arange(40) % 3 == 0).astype(np.int64),
                             np.zeros(40, np.int64)), bad)
    finally:
        datasets.check_metres = real
    assert main(["fit", str(bad), "--out", str(tmp_path / "fit")]) == 2
    err = capsys.readouterr().err
    assert "mm.gpioius" in err and "probably in millimetres" in err and "resolution" not in err


def test_a_mistyped_option_gets_its_commands_usage_and_the_nearest_option(capsys):
    """Issue 35, item 8: `--max-travle` printed the top-level usage."""
    with pytest.raises(SystemExit) as done:
        main(["simulate3d", "--max-travle", "0.3"])
    assert done.value.code == 2
    err = capsys.readouterr().err
    assert "usage: gpioius simulate3d" in err and "did you mean --max-travel?" in err
    with pytest.raises(SystemExit):
        main(["fit", str(EXAMPLE), "--zzz"])
    err = capsys.readouterr().err
    assert "usage: gpioius fit" in err and "unrecognized arguments: --zzz" in err and "did you mean" not in err


def test_warnings_reach_the_user_as_one_line(capsys, monkeypatch, tmp_path):
    """Issue 35, item 10: warnings reached users raw, with a line of library source."""
    import warnings as w

    import torch_gpioius.fitting as offline

    def fit(*args, **kwargs):
        w.warn("GPIOIS.fit: K_t's fit stopped at its cap", RuntimeWarning)
        return {"n": 1, "n_inner": 1, "n_outer": 0, "lengthscale": 0.1, "noise": 0.006, "mll": 1.0, "estimate": True,
                "settings": None}

    monkeypatch.setattr(offline, "fit_dataset", fit)
    assert main(["fit", str(EXAMPLE)]) == 0
    err = capsys.readouterr().err
    assert "gpioius: warning: GPIOIS.fit: K_t's fit stopped at its cap" in err
    assert "RuntimeWarning" not in err and "w.warn(" not in err and ".py:" not in err


def test_an_exploration_says_once_how_many_fits_stopped_short(monkeypatch):
    import warnings as w

    import torch_gpioius as tg
    from torch_gpioius.models.gpiois import GPIOIS, FitNotConvergedWarning

    real = GPIOIS.fit

    def fit(self, *args, **kwargs):
        out = real(self, *args, **kwargs)
        w.warn("GPIOIS.fit: stopped short", FitNotConvergedWarning)
        return out

    monkeypatch.setattr(GPIOIS, "fit", fit)
    with w.catch_warnings(record=True) as caught:
        w.simplefilter("always")
        tg.explore(tg.sim.paper_objects_2d()["A"], max_steps=4)
    mine = [str(c.message) for c in caught if issubclass(c.category, FitNotConvergedWarning)]
    assert mine[-1].startswith("explore: K_t's fit stopped short of the gradient tolerance")
    assert "at 4 of 4 steps" in mine[-1]
    assert len(mine) <= 2          # the first fit (before exploring) may warn itself; the steps' are counted


def test_fit_reads_a_users_contacts_csv_and_cloud_with_units_and_camera_free_space(tmp_path, capsys):
    """Issue 35, item 5: `gpioius fit touches.csv` gave "bad magic bytes" and --cloud was unknown."""
    import json

    import trimesh

    rng = np.random.default_rng(0)
    d = rng.normal(size=(40, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    c = np.array([500.0, 0.0, 250.0])                                   # millimetres
    rows = ["x,y,z,label"] + [f"{p[0]:.2f},{p[1]:.2f},{p[2]:.2f},contact" for p in d[:30] * 80 + c] + \
        [f"{p[0]:.2f},{p[1]:.2f},{p[2]:.2f},free" for p in d[30:] * 110 + c]
    (tmp_path / "touch.csv").write_text("\n".join(rows) + "\n")
    shell = trimesh.creation.icosphere(3, radius=90).vertices + c
    trimesh.PointCloud(shell[shell[:, 0] < c[0] + 30]).export(tmp_path / "cloud.ply")
    csv, cloud = str(tmp_path / "touch.csv"), str(tmp_path / "cloud.ply")
    assert main(["fit", csv, "--cloud", cloud]) == 2                     # metres assumed: named as units
    assert "--units mm" in capsys.readouterr().err
    out = tmp_path / "fit"
    assert main(["fit", csv, "--cloud", cloud, "--units", "mm", "--voxel", "0.02", "--out", str(out)]) == 0
    plain = json.loads((out / "fit.json").read_text())
    repeats = EstimatorSettings.default().labels.contact_repeats         # each contact as often as a run counts it
    assert plain["n_inner"] == 30 * repeats + 10 and plain["n_outer"] > 100
    assert main(["fit", csv, "--cloud", cloud, "--units", "mm", "--voxel", "0.02", "--camera-origin", "-500 0 600",
                 "--out", str(out)]) == 0
    with_free = json.loads((out / "fit.json").read_text())
    assert with_free["n_outer"] > plain["n_outer"]                       # the camera's free space was added
    assert "touch.csv: " in capsys.readouterr().out and with_free["n_inner"] == 30 * repeats + 10
    assert main(["fit", str(EXAMPLE), "--cloud", cloud]) == 2            # a .gpioius file holds its own cloud
    assert "go with a contacts CSV" in capsys.readouterr().err
    bad = tmp_path / "bad"
    assert main(["fit", csv, "--cloud", cloud, "--units", "mm", "--camera-origin", "a b c", "--out", str(bad)]) == 2
    assert "--camera-origin: expected three numbers" in capsys.readouterr().err and not bad.exists()


def test_fit_takes_several_captures_each_with_its_own_camera(tmp_path, capsys):
    """Issue 34, item 4: two captures of a sphere from opposite sides, each with its camera: every free-space point
    lies in front of the sphere on its own capture's side (a merged cloud with one origin put the second view's free
    space on rays to the first camera, through the body)."""
    import trimesh

    from torch_gpioius.io.importers import dataset_from_files

    c = np.array([0.5, 0.0, 0.25])
    rows = ["x,y,z,label", f"{c[0] + 0.1},{c[1]},{c[2]},contact"]
    (tmp_path / "touch.csv").write_text("\n".join(rows) + "\n")
    shell = trimesh.creation.icosphere(3, radius=0.1).vertices + c
    left, right = shell[shell[:, 1] < -0.02], shell[shell[:, 1] > 0.02]
    trimesh.PointCloud(left).export(tmp_path / "left.ply")
    trimesh.PointCloud(right).export(tmp_path / "right.ply")
    eyes = [c + [0, -1.0, 0], c + [0, 1.0, 0]]
    files = [str(tmp_path / "left.ply"), str(tmp_path / "right.ply")]
    paper_every_point = EstimatorSettings.paper().with_voxel(0)
    ds = dataset_from_files(tmp_path / "touch.csv", files, camera_origin=eyes, settings=paper_every_point)
    free = ds.x[(ds.task == 1) & (ds.y == 1)]
    assert len(free) == len(left) + len(right)
    r = np.linalg.norm(free - c, axis=1)
    # each free point 5 cm in front of a seen point, on its own capture's side, never inside the sphere
    assert (r > 0.1 + 1e-3).all() and (r < 0.15 + 1e-6).all() and (np.abs(free[:, 1] - c[1]) > 0.02).all()
    assert ds.meta["camera_origin"] == [list(e) for e in eyes]
    out = tmp_path / "fit"
    assert main(["fit", str(tmp_path / "touch.csv"), "--cloud", files[0], "--cloud", files[1], "--voxel", "0",
                 "--camera-origin", " ".join(map(str, eyes[0])), "--camera-origin", " ".join(map(str, eyes[1])),
                 "--out", str(out)]) == 0
    assert f"{EstimatorSettings.default().labels.contact_repeats} inner" in capsys.readouterr().out
    assert main(["fit", str(tmp_path / "touch.csv"), "--cloud", files[0], "--cloud", files[1],
                 "--camera-origin", "0 0 0"]) == 2
    assert "1 given for 2 --cloud" in capsys.readouterr().err
    with pytest.raises(Exception, match=r"3 origin\(s\) for 2 point clouds"):
        dataset_from_files(tmp_path / "touch.csv", files, camera_origin=[eyes[0], eyes[1], None])
    # a capture without camera: its points, no free space
    one = dataset_from_files(tmp_path / "touch.csv", files, camera_origin=[eyes[0], None],
                             settings=paper_every_point)
    assert int(((one.task == 1) & (one.y == 1)).sum()) == len(left)


def test_fit_says_when_there_is_no_estimate(tmp_path, capsys):
    """Issue 33, item 5: a fit whose inner zero level has no surface in the data's box said nothing."""
    from torch_gpioius.io.datasets import Dataset, save_dataset

    rng = np.random.default_rng(1)
    x = rng.uniform(-0.1, 0.1, size=(30, 2))
    free_only = save_dataset(Dataset(x, np.ones(30), np.zeros(30, np.int64), np.zeros(30, np.int64)),
                             tmp_path / "free.gpioius")                # free space only: mu > 0 everywhere
    assert main(["fit", str(free_only)]) == 0
    assert "no estimate: no surface to show or export; only 0 contact(s): too few" in capsys.readouterr().out
    assert main(["fit", str(EXAMPLE)]) == 0
    assert "no estimate" not in capsys.readouterr().out


def test_kernel_lengths_have_one_range_at_every_door_and_a_short_one_is_named_as_the_cause(tmp_path, capsys):
    """Issue 60, item 13: `fit --theta 500` was accepted, `--lengthscale 25` refused, scene files took (0.001, 10]; a
    length of 0.1 mm ended in "no estimate ... (too few contacts, or units other than metres?)"."""
    from torch_gpioius.io.datasets import load_dataset
    from torch_gpioius.fitting import why_no_estimate
    from torch_gpioius.kernels import KernelChoice

    for option in ("--theta", "--lengthscale"):
        for bad in ("500", "25", "0.0001"):
            for command in (["fit", str(EXAMPLE)], ["study", "--world", "planar", "--out", str(tmp_path / "s")]):
                with pytest.raises(SystemExit):
                    main([*command, option, bad])
                err = capsys.readouterr().err
                assert f"{option}: {float(bad):g} m is" in err and ("below 1 mm" in err or "above 10 m" in err), err
    for bad in (25.0, 1e-4):
        with pytest.raises(ValueError, match="lengthscale: .* m is (below 1 mm|above 10 m)"):
            KernelChoice("matern52", bad)
    ds = load_dataset(EXAMPLE)
    assert "the kernel's length (0.05 mm) is far below the spacing" in why_no_estimate(ds, 5e-5)


def test_replay_locks_its_folder(tmp_path, capsys):
    """Issue 51, item 6: two replays into one folder both exited 0, and one run's output was lost."""
    from torch_gpioius.io.outputs import FolderLock

    out = tmp_path / "rep"
    out.mkdir()
    with FolderLock(out, "gpioius replay"):
        assert main(["replay", "data/example_2d.gpioius", "--out", str(out), "--every", "40", "--quiet"]) == 2
    assert "another gpioius replay (pid" in capsys.readouterr().err
    assert not (out / "records.csv").exists()
    assert main(["replay", "data/example_2d.gpioius", "--out", str(out), "--every", "40", "--quiet"]) == 0
    assert (out / "records.csv").exists() and not list(out.glob(".staging.*"))


def test_fit_writes_a_folder_for_3d_contacts_alone(tmp_path, capsys):
    """Issue 51, item 20: `gpioius fit contacts.csv --out DIR` (3-D contacts, no cloud) crashed in _plot_estimate
    with "GPIS.predict() got an unexpected keyword argument 'task'" and left only the lock files."""
    import json

    rng = np.random.default_rng(4)
    d = rng.normal(size=(40, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    c = np.array([0.5, 0.0, 0.25])
    rows = ["x,y,z,label"] + [f"{p[0]:.5f},{p[1]:.5f},{p[2]:.5f},contact" for p in d[:30] * 0.08 + c] + \
        [f"{p[0]:.5f},{p[1]:.5f},{p[2]:.5f},free" for p in d[30:] * 0.13 + c]
    (tmp_path / "touch.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "fit"
    assert main(["fit", str(tmp_path / "touch.csv"), "--out", str(out)]) == 0
    assert "tactile-only GPIS" in capsys.readouterr().out
    assert (out / "fit.png").stat().st_size > 0 and json.loads((out / "fit.json").read_text())["n_outer"] == 0
    import torch_gpioius as tg

    model = tg.load_checkpoint(out / "model.pt")
    q = torch.tensor([[0.5, 0.0, 0.25]], dtype=torch.float64)
    assert torch.equal(model.predict(q, task=0)[0], model.predict(q)[0])
    with pytest.raises(ValueError, match="a GPIS models the inner shape only"):
        model.predict(q, task="outer")


def test_unquoted_numbers_get_a_hint_at_the_quotes(capsys):
    """Issue 51, item 27: `--camera-origin 0.5 -0.8 0.45` without quotes gave "unrecognized arguments: -0.8 0.45"."""
    with pytest.raises(SystemExit):
        main(["fit", "c.csv", "--cloud", "a.ply", "--camera-origin", "0.5", "-0.8", "0.45"])
    err = capsys.readouterr().err
    assert "unrecognized arguments: -0.8 0.45" in err
    assert '--camera-origin takes its numbers as one quoted argument: --camera-origin "0.5 -0.8 0.45"' in err


def test_missing_extras_are_named_with_both_ways_to_install():
    """Issue 51, item 27: missing-extra messages said `pip install 'torch_gpioius[viewer]'` while the README installs
    with `-e ".[...]"`."""
    from torch_gpioius.core.extras import install_hint

    assert install_hint("viewer") == "pip install 'torch_gpioius[viewer]' (in a checkout: pip install -e '.[viewer]')"
    import pathlib

    for path in pathlib.Path("torch_gpioius").rglob("*.py"):
        if path.name != "_extras.py":                # every other message asks install_hint
            text = path.read_text()
            assert "pip install torch_gpioius[" not in text, path           # unquoted: a glob in zsh
            assert ": pip install 'torch_gpioius[" not in text, path         # a message: install_hint says it


def test_fit_on_one_contact_and_one_seen_point_says_it_cannot_tell(tmp_path, capsys):
    """Issue 51, item 13 (and issue 52, item 5): `fit --learn all` on one contact and one cloud point reported a
    correlation of 1.0000 [0.79, 1.00], "the outer shape predicts the inner one"."""
    import json

    (tmp_path / "c.csv").write_text("x,y,z,label\n0.5,0,0.25,contact\n0.5,0,0.35,free\n")
    np.savez(tmp_path / "cloud.npz", points=np.array([[0.5, 0.0, 0.258]]))
    out = tmp_path / "fit"
    assert main(["fit", str(tmp_path / "c.csv"), "--cloud", str(tmp_path / "cloud.npz"), "--voxel", "0",
                 "--learn", "all", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "too few observations to tell: the contacts cover 1 and the seen surface 1 patch(es)" in printed
    assert "predicts the inner one" not in printed
    support = json.loads((out / "fit.json").read_text())["similarity_support"]
    assert support["inner"] == 1 and support["outer"] == 1 and support["enough"] is False
    assert main(["fit", str(EXAMPLE)]) == 0                      # the example: enough (4 and 10 patches)
    assert "too few" not in capsys.readouterr().out


def test_fit_sizes_the_kernel_to_the_clouds_and_takes_a_kernel_or_length_in_its_place(tmp_path, capsys):
    """The default settings' length is a fifth of the clouds' largest extent (4-10 cm); ``--lengthscale`` fixes it
    (the rule dropped), ``--kernel`` alone changes the kind and keeps the rule, on a user's files and on a dataset
    file alike; ``--theta`` beside them is refused by name."""
    import json

    import trimesh

    import torch_gpioius as tg

    c = np.array([0.5, 0.0, 0.25])
    shell = trimesh.creation.icosphere(2, radius=0.2).vertices + c          # a 40 cm body: 8 cm
    rows = ["x,y,z,label"] + [f"{x},{y},{z},contact" for x, y, z in shell[shell[:, 2] > c[2] + 0.15][:12]]
    (tmp_path / "touch.csv").write_text("\n".join(rows) + "\n")
    trimesh.PointCloud(shell + 0.01 * (shell - c) / 0.2).export(tmp_path / "cover.ply")
    files = [str(tmp_path / "touch.csv"), "--cloud", str(tmp_path / "cover.ply"), "--camera-origin", "0.5 -1 0.25"]

    def fitted(*extra):
        out = tmp_path / f"fit{len(list(tmp_path.glob('fit*')))}"
        assert main(["fit", *files, *extra, "--out", str(out)]) == 0
        capsys.readouterr()
        return json.loads((out / "fit.json").read_text())

    rule = fitted()
    assert rule["kernel"]["kernel"] == "Matern52" and rule["lengthscale"] == pytest.approx(0.084, abs=1e-12)
    assert rule["settings"]["length_rule"] == {"fraction": 0.2, "lo": 0.04, "hi": 0.1}
    fixed = fitted("--lengthscale", "0.06")
    assert fixed["lengthscale"] == pytest.approx(0.06) and fixed["settings"]["length_rule"] is None
    imq = fitted("--kernel", "imq")
    assert imq["kernel"]["kernel"] == "InverseMultiquadric" and imq["lengthscale"] == pytest.approx(0.084)
    # a dataset file: the choice on top of the kernel it was labelled with
    ds = tg.io.importers.dataset_from_files(tmp_path / "touch.csv", tmp_path / "cover.ply",
                                            camera_origin=[0.5, -1, 0.25])
    tg.save_dataset(ds, tmp_path / "mine.gpioius")
    assert main(["fit", str(tmp_path / "mine.gpioius"), "--lengthscale", "0.05", "--out", str(tmp_path / "d")]) == 0
    info = json.loads((tmp_path / "d" / "fit.json").read_text())
    assert info["kernel"]["kernel"] == "Matern52" and info["lengthscale"] == pytest.approx(0.05)
    assert main(["fit", *files, "--lengthscale", "0.05", "--theta", "0.1"]) == 2
    assert "--theta (deprecated)" in capsys.readouterr().err


def test_a_refused_scene_leaves_no_folder_and_a_fit_no_lock(tmp_path, capsys):
    """Issue 60, item 19: a refused `simulate3d` scene left its output folder (`.gpioius-output.json`, `.lock`), and a
    successful `fit` its `.lock`."""
    scene = tmp_path / "broken.toml"
    scene.write_text('name = "broken"\n[object]\nmesh = "no-such-mesh.stl"\n[cover]\nkind = "tight"\ngap = 0.008\n')
    out = tmp_path / "sim"
    assert main(["simulate3d", "--scene", str(scene), "--smoke", "--quiet", "--out", str(out)]) == 2
    assert "no-such-mesh.stl" in capsys.readouterr().err and not out.exists()
    fit = tmp_path / "fit"
    assert main(["fit", str(EXAMPLE), "--out", str(fit)]) == 0
    assert sorted(p.name for p in fit.iterdir()) == [".gpioius-output.json", "fit.json", "fit.png", "model.pt"]
    assert f"wrote {fit / 'model.pt'}, {fit / 'fit.png'} and {fit / 'fit.json'}" in capsys.readouterr().out


def test_fit_writes_the_simple_baselines_from_the_same_files(tmp_path, capsys):
    """Issue 61: `gpioius fit --out` sets the simple baselines beside the estimate, from the same observations: the
    camera's surface alone, and shrunk by the gap the first five (or all) contacts measure: 1 cm on this sphere."""
    import json

    import trimesh

    from tests.userfiles import CENTRE, EYES, sphere_files

    csv, (left, right) = sphere_files(tmp_path, contacts=20, cover=800)
    out = tmp_path / "fit"
    assert main(["fit", str(csv), "--cloud", str(left), "--cloud", str(right), "--camera-origin",
                 " ".join(map(str, EYES[0])), "--camera-origin", " ".join(map(str, EYES[1])), "--out", str(out)]) == 0
    assert "wrote the simple baselines from the same observations" in capsys.readouterr().out
    info = json.loads((out / "fit.json").read_text())["baselines"]
    assert set(info) >= {"vision", "vision-shrunk-5", "vision-shrunk-all"}
    for name in ("vision-shrunk-5", "vision-shrunk-all"):
        assert abs(info[name]["gap"] - 0.01) < 0.003, info[name]
    r = {name: np.median(np.linalg.norm(trimesh.load(out / "baselines" / f"{name}.ply").vertices - CENTRE, axis=1))
         for name in ("vision", "vision-shrunk-5")}
    assert abs(r["vision"] - 0.07) < 0.004 and abs(r["vision-shrunk-5"] - 0.06) < 0.004, r


def test_fit_corrects_a_miscalibrated_cameras_captures_when_asked_and_records_it(tmp_path, capsys):
    """Issue 63, item 2: `gpioius fit --camera-bound` corrects each capture from the contacts, prints each
    correction and writes them to fit.json; a dataset file (its cloud already in the model's frame) refuses it."""
    import json

    from tests.io.test_importers import _box_files

    csv, clouds, eyes, _ = _box_files(tmp_path, "6mm,1deg")
    args = ["fit", str(csv)]
    for cloud, eye in zip(clouds, eyes):
        args += ["--cloud", str(cloud), "--camera-origin", " ".join(f"{v:.6f}" for v in eye)]
    out = tmp_path / "fit"
    assert main([*args, "--camera-bound", "12mm,2deg", "--out", str(out), "--quiet"]) == 0
    said = capsys.readouterr()
    printed = said.out
    assert "check the camera's calibration" in said.err                  # the large corrections, by file
    assert "captures corrected from the contacts (within 12 mm and 2 deg)" in printed
    record = json.loads((out / "fit.json").read_text())["camera_corrections"]
    assert len(record["captures"]) == 3 and record["misfit_after_mm"] < record["misfit_before_mm"]
    assert main(["fit", str(out / "model.pt"), "--camera-bound", "6mm,1deg"]) == 2
    assert "--camera-bound and --table go with a contacts CSV" in capsys.readouterr().err
    assert main([*args, "--table", "0.13", "--out", str(tmp_path / "t"), "--quiet"]) == 2
    assert "--table holds the captures to the table while --camera-bound corrects them" in capsys.readouterr().err
