"""Studies over seeds: the statistics against closed forms, a sequential sweep that skips finished runs and
reproduces itself, seeds that perturb the world, and a real local Ray sweep that survives a killed worker."""

import math
import csv
import json
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import wilcoxon

from torch_gpioius.kernels import KernelChoice
from torch_gpioius.models.overrides import EstimatorOverrides
from torch_gpioius.studies.stats import median_interval, paired_difference
from torch_gpioius.studies.study import make_world, run_sweep

from tests.scenes import ball_scene

ROOT = Path(__file__).resolve().parents[2]


def test_order_statistic_interval_of_the_median():
    x = np.arange(10.0)[::-1]                     # n = 10: ranks 2 and 9, coverage 1 - 2 P(Bin(10, 1/2) <= 1)
    m = median_interval(x)
    assert (m["median"], m["lo"], m["hi"], m["n"]) == (4.5, 1.0, 8.0, 10)
    assert m["coverage"] == pytest.approx(1 - 2 * (1 + 10) / 1024)
    small = median_interval([3.0, 1.0, 2.0])     # no 95 % interval exists: the range, with its coverage
    assert (small["lo"], small["hi"]) == (1.0, 3.0) and small["coverage"] == pytest.approx(0.75)
    assert np.isnan(median_interval([np.nan], failed="drop")["median"])      # nothing entered
    assert median_interval([np.nan])["median"] == np.inf                    # a failure is the worst value
    a, b = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.5]), np.array([1.5, 2.1, 3.9, 4.2, 6.0, 6.0])
    d = paired_difference(a, b)
    assert d["p_wilcoxon"] == pytest.approx(wilcoxon(a - b).pvalue)
    assert d["median"] == pytest.approx(np.median(a - b)) and d["wins"] == 5


def test_seed_zero_is_the_unperturbed_world_and_seeds_perturb_it():
    from torch_gpioius.sim import paper_objects_2d
    base = paper_objects_2d()["A"]
    assert make_world("planar", "A", 0).fingerprint() == base.fingerprint()
    w1, w2 = make_world("planar", "A", 1), make_world("planar", "A", 2)
    assert w1.fingerprint() != base.fingerprint() != w2.fingerprint()
    shift = np.linalg.norm(w1.start - base.start)
    angle = np.degrees(np.arccos(np.clip(w1.direction @ base.direction, -1, 1)))
    assert shift <= 0.02 + 1e-12 and angle <= 10 + 1e-9
    assert make_world("planar", "A", 1).fingerprint() == w1.fingerprint()      # deterministic in the seed


def test_sequential_sweep_writes_its_outputs_skips_finished_runs_and_repeats(tmp_path):
    a = run_sweep("planar", objects=["A"], seeds=2, out=tmp_path / "a", smoke=True, backend="local", progress=False)
    assert a["runs"] == 4 and a["skipped"] == 0
    rows = list(csv.DictReader(open(tmp_path / "a" / "runs.csv")))
    assert {"object", "mode", "seed", "final_hausdorff"} <= set(rows[0]) and len(rows) == 4
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    entry = summary["objects"]["A"]["visual-tactile"]
    assert {"median", "lo", "hi"} <= set(entry["final_hausdorff"]) and entry["n"] == 2
    for name in ("transitions_A.png", "similarity_bands.png", "paired_final_hausdorff.png", "paired_final_chamfer.png",
                 "summary.md"):
        assert (tmp_path / "a" / name).stat().st_size > 0
    assert len(list((tmp_path / "a" / "logs").glob("*.gpioius"))) == 4
    again = run_sweep("planar", objects=["A"], seeds=2, out=tmp_path / "a", smoke=True, backend="local", progress=False)
    assert again["skipped"] == 4
    run_sweep("planar", objects=["A"], seeds=2, out=tmp_path / "b", smoke=True, backend="local", progress=False)
    rows_b = list(csv.DictReader(open(tmp_path / "b" / "runs.csv")))
    for ra, rb in zip(rows, rows_b):                               # the same seed gives identical numbers
        assert ra["final_hausdorff"] == rb["final_hausdorff"] and ra["travel"] == rb["travel"]


def test_bad_sweep_arguments(tmp_path):
    with pytest.raises(ValueError, match="world"):
        run_sweep("4d", out=tmp_path)
    with pytest.raises(ValueError, match="modes"):
        run_sweep("planar", modes=["visual"], out=tmp_path)
    with pytest.raises(ValueError, match="objects"):
        run_sweep("planar", objects=["Q"], out=tmp_path)
    with pytest.raises(ValueError, match="seeds"):
        run_sweep("planar", seeds=0, out=tmp_path)
    with pytest.raises(ValueError, match=r"settings: applies to the worlds that take presets \(forcefield, mujoco"):
        run_sweep("planar", settings="default", out=tmp_path)
    with pytest.raises(ValueError, match="settings"):
        run_sweep("forcefield", objects=["E"], settings="mine", out=tmp_path)
    with pytest.raises(ValueError, match="workers: must be a positive integer"):
        run_sweep("planar", workers=0, out=tmp_path)


def test_workers_are_capped_at_the_cores_of_a_local_run():
    """Issue 51, item 17: `study --workers 1000` started one Ray process per run."""
    from torch_gpioius.studies.study_plan import _checked_workers

    cores = os.cpu_count()
    with pytest.warns(UserWarning, match=f"workers: 1000 parallel runs on {cores} cores .* running {cores} at a time"):
        assert _checked_workers(1000, None) == cores
    assert _checked_workers(1, None) == 1 and _checked_workers(None, None) is None
    assert _checked_workers(1000, "ray://head:10001") == 1000          # a cluster's CPUs bound it there


def test_a_studys_settings_reach_every_run_built_in_objects_and_scene_files_alike(tmp_path):
    from torch_gpioius.studies.study import StudyPlan

    kw = dict(world="forcefield", objects=["E"], modes=["visual-tactile"], seeds=2, out=tmp_path, workers=1,
              address=None, max_travel=None, max_steps=None, smoke=True, progress=False, threads=1, backend="local",
              force=False, scenes=[str(ROOT / "examples/scenes/real/duck-tight.toml")], touch="point",
              outer_tol=None, device=None, settings="default")
    specs = StudyPlan.checked(**kw)._specs(tmp_path)
    assert {s.object for s in specs} == {"E", "duck-tight"} and {s.settings for s in specs} == {"default"}


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_a_real_ray_sweep_survives_a_killed_worker(tmp_path):
    pytest.importorskip("ray")
    out = tmp_path / "sweep"
    cmd = [sys.executable, "-m", "torch_gpioius.cli", "study", "--world", "planar", "--objects", "A,D", "--seeds", "2",
           "--smoke", "--max-steps", "25", "--workers", "2", "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                            env=dict(os.environ, OMP_NUM_THREADS="1"))
    killed = None
    deadline = time.monotonic() + 240
    while killed is None and time.monotonic() < deadline and proc.poll() is None:
        for marker in (out / "running").glob("*.pid") if (out / "running").exists() else []:
            try:
                pid = int(marker.read_text())
                os.kill(pid, signal.SIGKILL)
                killed = marker.stem
                break
            except (ValueError, ProcessLookupError, FileNotFoundError):
                continue
        time.sleep(0.01)
    stdout, stderr = proc.communicate(timeout=600)
    assert killed is not None, "no run was caught running"
    assert proc.returncode == 0, stderr[-2000:]
    rows = list(csv.DictReader(open(out / "runs.csv")))
    keys = [(r["object"], r["mode"], r["seed"]) for r in rows]
    assert len(keys) == 8 and len(set(keys)) == 8                 # nothing lost, nothing duplicated
    assert len(list((out / "runs").glob("*.json"))) == 8 and not list((out / "runs").glob("*.tmp"))
    assert killed in {p.stem for p in (out / "runs").glob("*.json")}   # the killed run was retried to the end
    assert "on Ray" in stdout
    assert "Token authentication" not in stdout + stderr           # Ray's banner is not printed


def test_a_second_study_into_the_same_folder_is_refused_while_the_first_runs(tmp_path):
    """Two drivers on one --out used to share temporary files and corrupt each other's logs; now the folder is
    locked for the whole sweep and the second driver stops at once, naming the first one's pid."""
    from torch_gpioius.io.outputs import FolderLock

    out = tmp_path / "s"
    out.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from torch_gpioius.io.outputs import "
                               "FolderLock; l = FolderLock(sys.argv[1]).acquire(); print('locked', flush=True); "
                               "time.sleep(60)", str(out)], stdout=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(RuntimeError, match=rf"another gpioius study \(pid {holder.pid}\) is writing there"):
            run_sweep("planar", objects=["A"], seeds=1, out=out, smoke=True, backend="local", progress=False)
    finally:
        holder.kill()
        holder.wait()
    assert not (out / "runs").exists()                            # nothing was written by the refused sweep
    with FolderLock(out):                                         # the kernel released the dead holder's lock
        pass


def test_study_folders_belong_to_one_world_and_are_never_someone_elses(tmp_path):
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "runs.csv").write_text("my,own,table\n")
    with pytest.raises(FileExistsError, match="not empty and was not written by `gpioius study`; pass --force"):
        run_sweep("planar", objects=["A"], seeds=1, out=foreign, smoke=True, backend="local", progress=False)
    assert (foreign / "runs.csv").read_text() == "my,own,table\n"
    out = tmp_path / "s"
    run_sweep("planar", objects=["A"], modes=["tactile", "tactile"], seeds=1, out=out, smoke=True, backend="local",
              progress=False)
    assert sorted(p.name for p in (out / "runs").glob("*.json")) == ["A_tactile_0.json"]    # a mode counts once
    assert not (out / "running").exists()                         # no empty running/ folder is left behind
    with pytest.raises(FileExistsError, match=r"world='planar'.* this one is world='forcefield'"):
        run_sweep("forcefield", objects=["E"], seeds=1, out=out, smoke=True, backend="local", progress=False)
    with pytest.raises(ValueError, match=r"seeds: must be an integer in \[1, 10000\]"):
        run_sweep("planar", seeds=100_000_000, out=tmp_path / "big")


def test_damaged_and_foreign_run_files_are_named_and_damaged_runs_done_again(tmp_path):
    from torch_gpioius.studies.study import RunFileError, aggregate, read_run_file

    out = tmp_path / "s"
    run_sweep("planar", objects=["A"], modes=["tactile"], seeds=2, out=out, smoke=True, backend="local", progress=False)
    good = out / "runs" / "A_tactile_0.json"
    run = json.loads(good.read_text())
    bad_cases = {"truncated": good.read_text()[:40], "not an object": "[1, 2]",
                 "negative Hausdorff": json.dumps({**run, "series": {**run["series"], "hausdorff":
                                                                     [-0.1] * len(run["series"]["hausdorff"])}}),
                 "missing series": json.dumps({k: v for k, v in run.items() if k != "series"}),
                 "string seed": json.dumps({**run, "seed": "0"})}
    match = {"truncated": "not a readable run result", "not an object": "a JSON object",
             "negative Hausdorff": r"'series.hausdorff' holds a negative value", "missing series": "'series'",
             "string seed": "'seed' must be a non-negative integer"}
    for case, text in bad_cases.items():
        p = out / "runs" / "A_tactile_1.json"
        p.write_text(text)
        with pytest.raises(RunFileError, match=rf"A_tactile_1.json: .*{match[case]}"):
            read_run_file(p)
        with pytest.raises(RunFileError, match="A_tactile_1.json"):
            aggregate(out, world="2d")
    # a sweep sets the damaged file aside (kept, renamed) and does that run again
    with pytest.warns(RuntimeWarning, match="A_tactile_1.json: damaged or foreign result, renamed"):
        again = run_sweep("planar", objects=["A"], modes=["tactile"], seeds=2, out=out, smoke=True, backend="local",
                          progress=False)
    assert again["skipped"] == 1 and (out / "runs" / "A_tactile_1.json.invalid").exists()
    assert read_run_file(out / "runs" / "A_tactile_1.json")["seed"] == 1


def test_scene_files_run_as_objects_and_a_run_that_never_touches_is_a_counted_failure(tmp_path):
    """A scene file is an object of the study under its own name. A run whose approach misses the body (here the
    approach aims past the ball's side) fails before any estimate; it is recorded as a failure with its reason,
    counts as the worst result, and the study goes on."""
    ball = ball_scene(tmp_path)
    out = run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=tmp_path / "s",
                    smoke=True, backend="local", progress=False)
    rows = list(csv.DictReader(open(tmp_path / "s" / "runs.csv")))
    assert [r["object"] for r in rows] == ["ball"] and rows[0]["failed"] == ""
    assert float(rows[0]["contacts_on_body"]) == 1.0
    assert out["summary"]["objects"]["ball"]["visual-tactile"]["n"] == 1
    # a run that cannot start: the range lets the approach pass the ball and leave the workspace
    from torch_gpioius.studies.study import RunSpec, failure, read_run_file, run_one

    spec = RunSpec("forcefield", "ball", "tactile", 0, str(tmp_path / "s"), True, None, None, 1, str(ball))
    import torch_gpioius.studies.study_runs as study_runs

    real = study_runs.make_world

    def missing(*args, **kw):
        world = real(*args, **kw)
        world.start = world.start + np.array([0.08, 0.0, 0.0])      # 2 cm past the ball's side
        return world

    study_runs.make_world = missing                                  # the runs' module builds the world
    try:
        record = run_one(spec)
    finally:
        study_runs.make_world = real
    assert record["terminated"].startswith("refused: approach")
    assert failure(read_run_file(tmp_path / "s" / "runs" / f"{spec.key}.json")).startswith("approach")
    with pytest.raises(ValueError, match="also the names of objects"):
        run_sweep("forcefield", objects=["E"], scenes=[ball_scene(tmp_path, "E")], out=tmp_path / "t")
    with pytest.raises(ValueError, match="does not build scene files"):
        run_sweep("planar", scenes=[ball], out=tmp_path / "u")
    with pytest.raises(ValueError, match="two scene files"):
        other = tmp_path / "copy.toml"
        other.write_text(ball.read_text())
        run_sweep("forcefield", scenes=[ball, other], out=tmp_path / "v")


def test_camera_voxels_are_a_study_setting_recorded_per_run_and_per_folder(tmp_path):
    """--voxel reaches the camera: finer voxels keep more outer points; each run records its voxel and outer
    count; a folder holds one setting; bad values and the 2-D world are refused before anything runs."""
    ball = ball_scene(tmp_path)
    counts = {}
    for voxel, name in ((None, "default"), (0.01, "fine")):
        run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=tmp_path / name, smoke=True,
                  backend="local", progress=False, estimator=None if voxel is None else EstimatorOverrides(voxel=voxel))
        rows = list(csv.DictReader(open(tmp_path / name / "runs.csv")))
        assert rows[0]["failed"] == ""
        counts[name] = (float(rows[0]["voxel"]), int(rows[0]["n_outer"]))
    from torch_gpioius.sim.scenefile import load_scene

    # a scene file's own voxel is a tenth of the body, 2-5 cm (Scene3D.from_mesh's default settings)
    own = load_scene(ball).defaults.policy.voxel
    assert 0.02 <= own <= 0.05 and counts["default"][0] == own and counts["fine"][0] == 0.01
    assert counts["fine"][1] > 2 * counts["default"][1] > 0
    with pytest.raises(FileExistsError, match=r"voxel=0.01.* this one is voxel=.the world's default."):
        run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=tmp_path / "fine",
                  smoke=True, backend="local", progress=False)
    for bad in (-0.01, math.nan, 2.0, True):
        with pytest.raises(ValueError, match="voxel"):
            run_sweep("forcefield", scenes=[ball], seeds=1, out=tmp_path / "bad", estimator={"voxel": bad})
    with pytest.raises(ValueError, match="voxel-averaged"):
        run_sweep("planar", seeds=1, out=tmp_path / "planar", estimator=EstimatorOverrides(voxel=0.01))
    with pytest.warns(DeprecationWarning, match=r"run_sweep\(voxel=\): give settings=EstimatorOverrides"):
        with pytest.raises(ValueError, match="voxel-averaged"):         # the old keyword: the same setting
            run_sweep("planar", seeds=1, out=tmp_path / "planar", voxel=0.01)
    with pytest.raises(ValueError, match="voxel given beside the voxel argument"):
        with pytest.warns(DeprecationWarning):
            run_sweep("forcefield", seeds=1, out=tmp_path / "bad", voxel=0.01, estimator={"voxel": 0.02})
    assert not (tmp_path / "bad").exists() and not (tmp_path / "planar").exists()


def test_views_kernel_length_and_noise_are_study_settings_that_reach_every_run(tmp_path):
    """--views, --kernel, --lengthscale and --noise reach the scene and the model of each run (the record's length and
    sigma^2 are read back from the run's model; one view sees fewer outer points than the file's three), a folder
    holds one setting of each, and bad values are refused before anything runs."""
    ball = ball_scene(tmp_path)
    rows = {}
    for name, kw in (("own", {}), ("one", dict(views=1, estimator=EstimatorOverrides(kernel=KernelChoice("imq", 0.12),
                                                                                     noise=0.05)))):
        run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=tmp_path / name, smoke=True,
                  backend="local", progress=False, **kw)
        rows[name] = json.loads((tmp_path / name / "runs" / "ball_visual-tactile_0.json").read_text())
    own, one = rows["own"], rows["one"]
    assert own["views"] == "fixed+mirrored+wrist" and own["kernel"] == "Matern52"
    assert own["length"] == 0.04                                     # a 12 cm ball: a fifth, floored at 4 cm
    assert one["views"] == "fixed" and one["kernel"] == "InverseMultiquadric"
    assert one["length"] == pytest.approx(0.12, rel=1e-12) and one["noise"] == pytest.approx(0.05, rel=1e-12)
    assert 0 < one["n_outer"] < own["n_outer"]
    with pytest.raises(FileExistsError, match="views"):
        run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=tmp_path / "one",
                  smoke=True, backend="local", progress=False,
                  estimator=EstimatorOverrides(kernel=KernelChoice("imq", 0.12), noise=0.05))
    with pytest.raises(ValueError, match="lengthscale: 2000 m is above 10 m"):
        KernelChoice(lengthscale=2e3)
    bad = [(dict(views="side"), "views"), (dict(views=4), "views"), (dict(estimator={"kernel": "rbf"}), "kernel"),
           (dict(estimator={"kernel": 0.1}), "kernel"), (dict(estimator={"noise": 0.0}), "noise"),
           (dict(estimator={"noise": math.inf}), "noise")]
    for kw, match in bad:
        with pytest.raises(ValueError, match=match):
            run_sweep("forcefield", scenes=[ball], seeds=1, out=tmp_path / "bad", **kw)
    with pytest.raises(ValueError, match="views: the simulated camera views are those of forcefield, mujoco"):
        run_sweep("planar", seeds=1, out=tmp_path / "planar", views=1)
    assert not (tmp_path / "bad").exists() and not (tmp_path / "planar").exists()


def test_a_camera_error_is_a_study_setting_each_run_records_as_applied(tmp_path):
    """Issue 63, item 1: --camera-error reaches every view of every run, each run's record says what each view
    applied (the scene's own draw for that seed), a folder holds one error, and worlds without simulated cameras
    refuse it before anything runs."""
    from torch_gpioius.sim.scenefile import load_scene

    ball = ball_scene(tmp_path)
    run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=2, out=tmp_path / "off", smoke=True,
              backend="local", progress=False, camera_error="1deg,6mm", views=["fixed", "wrist"])
    for seed in (0, 1):
        run = json.loads((tmp_path / "off" / "runs" / f"ball_visual-tactile_{seed}.json").read_text())
        assert run["camera_error"]["asked"] == "6mm,1deg"
        truth = load_scene(ball, seed=seed).with_views(["fixed", "wrist"]).with_camera_error("6mm,1deg")
        assert run["camera_error"]["views"] == truth.camera_errors()
    with pytest.raises(FileExistsError, match="camera_error"):
        run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=tmp_path / "off", smoke=True,
                  backend="local", progress=False, camera_error="3mm,0.5deg", views=["fixed", "wrist"])
    # --camera-bound reaches each run's policy (its log's header) and its record; a folder holds one
    run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=tmp_path / "fix", smoke=True,
              backend="local", progress=False, camera_error="6mm,1deg", camera_bound="12mm,2deg")
    run = json.loads((tmp_path / "fix" / "runs" / "ball_visual-tactile_0.json").read_text())
    assert run["camera_bound"] == "12mm,2deg"
    from torch_gpioius.io.runs import load_run

    header = load_run(tmp_path / "fix" / "logs" / "ball_visual-tactile_0.gpioius").meta
    assert header["policy"]["camera_bound"] == [0.012, pytest.approx(math.radians(2))]
    with pytest.raises(FileExistsError, match="camera_bound"):
        run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=tmp_path / "fix", smoke=True,
                  backend="local", progress=False, camera_error="6mm,1deg")
    with pytest.raises(ValueError, match="give both a translation and a rotation"):
        run_sweep("forcefield", scenes=[ball], seeds=1, out=tmp_path / "bad", camera_bound="6mm")
    with pytest.raises(ValueError, match="a bound is a translation and a rotation"):
        run_sweep("forcefield", scenes=[ball], seeds=1, out=tmp_path / "bad", camera_bound="6mm,1deg,2x")
    # worse sensing (the error-source studies): no view moved, the record says what the cameras did
    run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=tmp_path / "noisy", smoke=True,
              backend="local", progress=False, camera_error="2x,20%holes")
    run = json.loads((tmp_path / "noisy" / "runs" / "ball_visual-tactile_0.json").read_text())
    assert run["camera_error"] == {"asked": "2x,20%holes", "views": {},
                                   "sensing": {"noise": 2.0, "dropout": 0.0, "holes": 0.2}}
    for world, kw, match in (("planar", {}, "planar world's cameras take no"),
                             ("forcefield", {"scenes": [ball]}, "not a size with a unit")):
        with pytest.raises(ValueError, match=match):
            run_sweep(world, seeds=1, out=tmp_path / "bad", camera_error="6" if kw else "6mm", **kw)
    assert not (tmp_path / "bad").exists()


def test_a_patch_study_runs_and_keeps_its_own_folder(tmp_path):
    ball = ball_scene(tmp_path)
    run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=tmp_path / "p", smoke=True,
              backend="local", progress=False, touch="patch")
    rows = list(csv.DictReader(open(tmp_path / "p" / "runs.csv")))
    assert rows[0]["failed"] == "" and json.loads((tmp_path / "p" / "runs" / "ball_visual-tactile_0.json")
                                                   .read_text())["touch"] == "patch"
    # the field's metrics reach runs.csv and the table (issue 34, item 5)
    assert 0 < float(rows[0]["final_chamfer"]) <= float(rows[0]["final_hausdorff"]) + 1e-9
    assert 0 <= float(rows[0]["final_fscore_5mm"]) <= 1 and "Chamfer final [cm]" in (tmp_path / "p" / "summary.md"
                                                                                      ).read_text()
    # issue 36: the record's step times are the median, 95th percentile and maximum of the log's planning steps
    # (every step after the approach, re-learning included)
    from torch_gpioius.io.datasets import read_records
    from torch_gpioius.io.logs import step_values

    record = json.loads((tmp_path / "p" / "runs" / "ball_visual-tactile_0.json").read_text())
    logged = [step_values(r.meta)["step_time"] for r in read_records(tmp_path / "p" / "logs" /
                                                                      "ball_visual-tactile_0.gpioius")
              if r.kind == "step"][1:]
    assert len(logged) == record["steps"] >= 2
    assert record["median_step_time"] == pytest.approx(statistics.median(logged), rel=1e-12)
    assert record["max_step_time"] == max(logged)
    assert record["p95_step_time"] == pytest.approx(np.percentile(logged, 95), rel=1e-12)
    assert record["median_step_time"] <= record["p95_step_time"] <= record["max_step_time"]
    assert float(rows[0]["p95_step_time"]) == pytest.approx(record["p95_step_time"], rel=1e-12)
    # issue 35, item 6: the point default read "touch=None"
    with pytest.raises(FileExistsError, match=r"touch='patch'.* this one is touch='point'"):
        run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=tmp_path / "p", smoke=True,
                  backend="local", progress=False)
    with pytest.raises(ValueError, match="touch"):
        run_sweep("forcefield", scenes=[ball], seeds=1, out=tmp_path / "q", touch="finger")


def _run(hausdorff, estimate=None, terminated="travel"):
    series = {"travel": [0.01 * i for i in range(len(hausdorff))], "hausdorff": hausdorff,
              "hausdorff_touched": hausdorff, "uncertainty": [0.1] * len(hausdorff),
              "similarity": [0.5] * len(hausdorff), "correlation": [0.9] * len(hausdorff),
              "correlation_lo": [0.5] * len(hausdorff), "correlation_hi": [1.0] * len(hausdorff)}
    if estimate is not None:
        series["estimate"] = estimate
    return {"world": "forcefield", "object": "X", "mode": "visual-tactile", "seed": 0, "terminated": terminated,
            "steps": len(hausdorff) - 1, "travel": series["travel"][-1], "budget": None, "wall_time": 1.0,
            "median_step_time": 0.01, "taps": 0, "recoveries": 0, "contacts_on_body": 1.0, "contacts_within": 1.0,
            "series": series}


def test_a_run_whose_final_estimate_vanished_is_failed_with_no_stale_value():
    """Issue 33, item 5: runs.csv gave an earlier step's Hausdorff (0.0515) as final_hausdorff, `failed` empty."""
    from torch_gpioius.studies.study_aggregate import _row, failure

    nan = math.nan
    lost = _run([0.08, nan, 0.0515, nan], [1.0, nan, 1.0, 0.0])
    row = _row(lost, {})
    assert failure(lost) == "no estimate" and row["failed"] == "no estimate"
    assert math.isnan(row["final_hausdorff"]) and math.isnan(row["final_uncertainty"])
    kept = _run([0.08, nan, 0.0515, 0.04], [1.0, nan, 1.0, 1.0])
    assert failure(kept) == "" and _row(kept, {})["final_hausdorff"] == 0.04
    old = _run([0.08, nan, 0.0515, nan])              # a run file written before the estimate series: as read then
    assert failure(old) == "" and _row(old, {})["final_hausdorff"] == 0.0515


def test_a_refused_scene_is_counted_by_what_its_message_says_not_by_the_objects_name():
    """Issue 63: the failed column kept a refused scene's first 60 characters, mostly the object's name and file
    ("scene: pybullet-random-110 (pybullet:random_urdfs/110/110.obj): inn"), so no two refusals counted together.
    The messages the benchmark's blobs were refused with, as the scenes word them, give their cause; another message
    keeps what follows the name."""
    from torch_gpioius.studies.study_aggregate import failure, failures_text

    name = "refused: scene: pybullet-random-1{} (pybullet:random_urdfs/1{}/1{}.obj): "
    messages = {
        "the body is nowhere more than 2.6 mm inside its surface (thin sheets, 37 pieces): a fingertip needs 3 mm to "
        "feel it from any side": "too thin to feel",
        "inner: not closed (1 hole(s) (4 boundary edges)); the repair (union by winding-number remesh at 1.2 mm) "
        "moves the surface by 8.8 mm, more than the 2.6 mm allowed (max_repair_distance); close the mesh in a mesh "
        "editor": "repair moves the surface",
        "direction: the approach ray only grazes the inner mesh (0.4 mm deep at most; at least 3 mm is needed to "
        "feel it)": "approach grazes",
        "pybullet-random-168 (/site-packages/pybullet_data/random_urdfs/168/168.obj): the mesh has no extent":
            "mesh has no extent",
        "inner: a bent handle of unknown kind": "inner: a bent handle of unknown kind"}
    reasons = []
    for k, (message, label) in enumerate(messages.items()):
        run = _run([0.08, 0.05])
        run["terminated"] = name.format(k, k, k) + message
        reasons.append(failure(run))
        assert reasons[-1] == "scene: " + label
    run["terminated"] = name.format(9, 9, 9) + "the body is nowhere more than 1.0 mm inside its surface"
    reasons.append(failure(run))
    assert failures_text(reasons) == ("6: 1 scene: approach grazes, 1 scene: inner: a bent handle of unknown kind, "
                                      "1 scene: mesh has no extent, 1 scene: repair moves the surface, "
                                      "2 scene: too thin to feel")


def test_run_files_with_a_bad_estimate_series_are_refused(tmp_path):
    from torch_gpioius.studies.study import RunFileError, read_run_file

    path = tmp_path / "r.json"
    path.write_text(json.dumps(_run([0.08, 0.05], [1.0, 2.0])))
    with pytest.raises(RunFileError, match="series.estimate"):
        read_run_file(path)


def test_a_fraction_whose_estimate_vanished_is_not_filled_by_a_later_one():
    from torch_gpioius.studies.study_aggregate import _at_travel

    nan = math.nan
    series = {"travel": [0.0, 0.05, 0.1, 0.2], "hausdorff": [0.09, nan, nan, 0.03], "estimate": [1.0, nan, 0.0, 1.0]}
    assert math.isnan(_at_travel(series, "hausdorff", 0.06))    # the step reaching it had no estimate
    assert _at_travel(series, "hausdorff", 0.15) == 0.03
    old = {k: v for k, v in series.items() if k != "estimate"}
    assert _at_travel(old, "hausdorff", 0.06) == 0.03            # older run files: as read then


def test_an_edited_scene_file_is_run_again_and_a_scene_that_cannot_be_built_is_a_failed_row(tmp_path, capsys):
    """Issue 51, items 7 and 8: a scene file edited after its study ran was reported with the old body's results
    ("1 runs (1 already done)"); and a scene that could not be built ended a 30-run study after the others ran,
    with no runs.csv."""
    import warnings

    from torch_gpioius.studies.study import read_run_file

    ball = ball_scene(tmp_path)
    broken = tmp_path / "broken.toml"
    (tmp_path / "broken.stl").write_text("solid nothing\nthis is not a mesh\n")
    broken.write_text(ball.read_text().replace('"ball"', '"broken"').replace("ball.stl", "broken.stl"))
    kw = dict(modes=["tactile"], seeds=1, out=tmp_path / "s", smoke=True, backend="local", progress=False)
    first = run_sweep("forcefield", scenes=[ball, broken], **kw)
    assert first["runs"] == 2 and first["skipped"] == 0
    rows = {r["object"]: r for r in csv.DictReader(open(tmp_path / "s" / "runs.csv"))}
    assert rows["ball"]["failed"] == "" and rows["broken"]["failed"].startswith("scene: ")
    assert "broken" in first["summary"]["objects"]
    old = read_run_file(tmp_path / "s" / "runs" / "ball_tactile_0.json")
    again = run_sweep("forcefield", scenes=[ball, broken], **kw)           # nothing changed: both done
    assert again["skipped"] == 2
    # the ball's cover edited: its run is another run now; the broken scene's is still done
    ball.write_text(ball.read_text().replace("gap = 0.008", "gap = 0.012"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        edited = run_sweep("forcefield", scenes=[ball, broken], **kw)
    assert edited["skipped"] == 1
    assert any("scene file as it was before it changed" in str(w.message) for w in caught)
    new = read_run_file(tmp_path / "s" / "runs" / "ball_tactile_0.json")
    assert new["scene_hash"] != old["scene_hash"]
    # issue 52: a run records the estimator's settings it ran with (a scene file: the default settings)
    assert new["estimator"]["name"] == "default" and new["estimator"]["kernel"]["kernel"] == "Matern52"
    assert (tmp_path / "s" / "runs" / "ball_tactile_0.json.stale").exists()
    assert [r["object"] for r in csv.DictReader(open(tmp_path / "s" / "runs.csv"))].count("ball") == 1


def test_claims_are_not_judged_on_too_few_seeds():
    """Issue 51, item 13: `study --seeds 2` judged the paper's claims "holds: yes" beside its own table's 50 %
    coverage and Wilcoxon p = 0.5."""
    from torch_gpioius.studies.study_aggregate import METRICS, MIN_SEEDS_TO_JUDGE, _claims, _summarize

    def rows(seeds):
        out = []
        for obj in ("E", "H"):
            for mode, h in (("visual-tactile", 0.01), ("tactile", 0.05)):
                for s in range(seeds):
                    r = {m: h + 1e-4 * s for m in METRICS}
                    r.update(final_correlation=0.9 if obj == "E" else 0.2, object=obj, mode=mode, seed=s, failed="",
                             taps=0, travel=1.5, recoveries=0, reapproaches=0, reapproach_share=0.0,
                             contacts_on_body=1.0, contacts_within=1.0)
                    out.append(r)
        return out

    few = _claims(_summarize(rows(2)))
    assert few and all(c["holds"] is None for c in few)
    assert all(c["measured"].startswith("too few seeds to judge (2;") for c in few)
    enough = _claims(_summarize(rows(MIN_SEEDS_TO_JUDGE)))
    assert all(c["holds"] is not None for c in enough)
    assert {c["claim"]: c["holds"] for c in enough}["E (tight): visual-tactile accurate from the beginning (10 % of "
                                                     "travel)"] is True


def test_a_local_study_runs_in_process_when_ray_cannot_start(tmp_path, monkeypatch, capsys):
    """Issue 51, item 18: Ray failing to start under a memory limit ended the study on a raw "node timed out during
    startup"."""
    pytest.importorskip("ray")
    import ray

    def refuse(*args, **kw):
        raise Exception("The current node timed out during startup. This could happen because some of the Ray "
                        "processes failed to startup.")

    monkeypatch.setattr(ray, "init", refuse)
    out = run_sweep("planar", objects=["A"], modes=["tactile"], seeds=2, out=tmp_path / "s", smoke=True,
                    backend="ray", progress=False, max_steps=3)
    assert out["runs"] == 2 and out["backend"] == "in-process (sequential)"
    assert "study: Ray could not start (Exception: The current node timed out" in capsys.readouterr().err
    assert len(list(csv.DictReader(open(tmp_path / "s" / "runs.csv")))) == 2


def test_an_object_set_runs_as_objects_with_its_cover_and_a_bad_set_is_refused_before_anything_runs(tmp_path):
    """Issue 54: ``gpioius study --objects primitives:A-B`` runs each object of the set (sized, standing on the
    table, under the chosen cover) in the force-field world; the runs' identity is the object's source, size and
    cover, so a second call skips them; a set in another world, a bad range and a cover without a set are refused
    before anything runs."""
    from torch_gpioius.cli import main

    out = tmp_path / "set"
    assert main(["study", "--world", "forcefield", "--objects", "primitives:3", "--cover", "wide", "--modes",
                 "tactile", "--seeds", "1", "--smoke", "--quiet", "--out", str(out)]) == 0
    record = json.loads((out / "runs" / "primitives-003_tactile_0.json").read_text())
    assert not record.get("failed") and record["scene_hash"].startswith("set:primitives:3:")
    assert record["scene_hash"].endswith(":wide") and record["estimator"]["name"] == "default"
    again = run_sweep("forcefield", objects=["primitives:3"], cover="wide", modes=["tactile"], seeds=1, out=out,
                      smoke=True, backend="local", progress=False)
    assert again["skipped"] == 1
    for kw, match in ((dict(world="planar", objects=["primitives:0-2"]), "built in the forcefield world"),
                      (dict(world="forcefield", objects=["primitives:5-2"]), "first <= last"),
                      (dict(world="forcefield", objects=["E"], cover="wide"), "applies to the objects of an object"),
                      (dict(world="forcefield", objects=["primitives:1"], cover="snug"), "cover: must be one of")):
        with pytest.raises(ValueError, match=match):
            run_sweep(seeds=1, out=tmp_path / "bad", smoke=True, backend="local", progress=False, **kw)
    assert not (tmp_path / "bad").exists()


def test_a_study_measures_on_the_schedule_when_asked(tmp_path):
    """Issue 54: `study --metrics-every schedule` measures the estimate at 10, 25 and 50 % of the travel and at the
    end (the fractions the summary reports), not every 5 steps; the setting is one per folder and checked first."""
    ball = ball_scene(tmp_path)
    run_sweep("forcefield", scenes=[ball], modes=["tactile"], seeds=1, out=tmp_path / "s", smoke=True,
              backend="local", progress=False, metrics_every="schedule")
    run = json.loads((tmp_path / "s" / "runs" / "ball_tactile_0.json").read_text())
    travel, h = np.asarray(run["series"]["travel"]), np.asarray(run["series"]["hausdorff"], dtype=float)
    budget = run["budget"]
    due = {0, len(travel) - 1} | {int(np.argmax(travel >= f * budget)) for f in (0.10, 0.25, 0.50)
                                  if (travel >= f * budget).any()}
    measured = set(np.flatnonzero(np.isfinite(h)).tolist())
    assert len(travel) - 1 in measured and measured <= due, (sorted(measured), sorted(due))
    with pytest.raises(FileExistsError, match="metrics_every"):
        run_sweep("forcefield", scenes=[ball], modes=["tactile"], seeds=1, out=tmp_path / "s", smoke=True,
                  backend="local", progress=False)
    for bad in (0, -2, "weekly", 1.5, True):
        with pytest.raises(ValueError, match="metrics_every: must be a number of steps >= 1 or 'schedule'"):
            run_sweep("forcefield", scenes=[ball], seeds=1, out=tmp_path / "bad", metrics_every=bad)


def test_a_study_keeps_to_the_travel_asked_for_with_or_without_a_measuring_schedule(tmp_path):
    """Issue 60, item 1: `study --max-travel 0.05` ran the world's own 1.5 m unless --metrics-every was given too (and
    a smoke run its 40 steps rather than 6 cm). The travel now stops each run whatever the schedule, the record says
    what was asked, and a run file of another travel (or of the releases that recorded none) is done again."""
    ball = ball_scene(tmp_path)
    for name, kw in (("plain", {}), ("schedule", {"metrics_every": "schedule"})):
        run_sweep("forcefield", scenes=[ball], modes=["tactile"], seeds=1, out=tmp_path / name, backend="local",
                  progress=False, max_travel=0.03, **kw)
        run = json.loads((tmp_path / name / "runs" / "ball_tactile_0.json").read_text())
        assert run["budget"] == 0.03
        # a step slides at most a few centimetres past the budget: the run stops at the first step beyond it
        assert 0.03 <= run["travel"] < 0.03 + 0.05 and run["steps"] < 40, (name, run["travel"], run["steps"])
    smoke = run_sweep("forcefield", scenes=[ball], modes=["tactile"], seeds=1, out=tmp_path / "smoke", smoke=True,
                      backend="local", progress=False)
    assert smoke["rows"][0]["budget"] == pytest.approx(0.06) and smoke["rows"][0]["travel"] < 0.06 + 0.05
    # a run file recorded without its budget (the releases that ignored --max-travel) is set aside and done again
    path = tmp_path / "plain" / "runs" / "ball_tactile_0.json"
    run = json.loads(path.read_text())
    path.write_text(json.dumps({**run, "budget": None}))
    with pytest.warns(RuntimeWarning, match="another travel budget"):
        again = run_sweep("forcefield", scenes=[ball], modes=["tactile"], seeds=1, out=tmp_path / "plain",
                          backend="local", progress=False, max_travel=0.03)
    assert again["skipped"] == 0 and (path.parent / (path.name + ".stale")).exists()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the watcher reads /proc")
def test_a_study_killed_with_sigkill_leaves_no_ray_process_behind(tmp_path):
    """Issue 60, item 10: `kill -9` of a study left Ray's DashboardAgent and RuntimeEnvAgent running (they ignore
    SIGTERM). The study's watcher ends every process Ray started for it once the study is gone."""
    pytest.importorskip("ray")
    from torch_gpioius.studies._reaper import _stat, descendants, running

    cmd = [sys.executable, "-m", "torch_gpioius.cli", "study", "--world", "planar", "--objects", "A,B", "--seeds", "3",
           "--max-steps", "60", "--workers", "2", "--out", str(tmp_path / "s"), "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT,
                            env=dict(os.environ, OMP_NUM_THREADS="1"))
    seen: dict[int, int] = {}
    deadline = time.monotonic() + 240
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            seen.update(descendants(proc.pid))
            names = {Path(f"/proc/{p}/cmdline").read_bytes() for p in seen if _stat(p)}
            if any(b"DashboardAgent" in n or b"RuntimeEnvAgent" in n for n in names):
                break
            time.sleep(0.2)
        assert proc.poll() is None, "the study ended before Ray's agents were seen"
        seen.update(descendants(proc.pid))
    finally:
        proc.kill()
        proc.wait()
    alive = seen
    for _ in range(100):                          # the watcher polls every 0.2 s
        # (a zombie has exited: killed, it waits for whoever adopted it to collect it, which under load is slow)
        alive = {p: s for p, s in alive.items() if running(p, s)}
        if not alive:
            break
        time.sleep(0.2)
    assert not alive, {p: Path(f"/proc/{p}/cmdline").read_bytes()[:60] for p in alive}


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the watcher reads /proc")
def test_the_watcher_ends_a_process_started_after_its_last_look_and_orphaned_before_the_kill(tmp_path):
    """CI: a study killed within half a second of Ray's agents starting left them running (the watcher's snapshots
    had not seen them, and their parent's death took them out of the study's tree). A process marked with the study's
    token is ended wherever it sits; an unmarked one is left alone."""
    from torch_gpioius.studies._reaper import TOKEN_VAR, _kill, _stat, marked

    token = f"test-{os.getpid()}-{time.monotonic_ns()}"
    pidfile = tmp_path / "pid"
    # a parent that starts a sleeper and exits at once: the sleeper is re-parented out of this test's tree
    spawn = ("import subprocess, sys; p = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'], "
             "start_new_session=True); open(sys.argv[1], 'w').write(str(p.pid))")
    subprocess.run([sys.executable, "-c", spawn, str(pidfile)], env=dict(os.environ, **{TOKEN_VAR: token}), check=True)
    subprocess.run([sys.executable, "-c", spawn, str(tmp_path / "other")], env=dict(os.environ), check=True)
    orphan, other = int(pidfile.read_text()), int((tmp_path / "other").read_text())
    try:
        assert set(marked(token)) == {orphan}
        _kill({}, token)
        for _ in range(50):
            if _stat(orphan) is None or Path(f"/proc/{orphan}/stat").read_text().split(") ")[1][0] == "Z":
                break
            time.sleep(0.1)
        else:
            raise AssertionError("the marked process is still running")
        assert _stat(other) is not None, "an unmarked process was killed"
    finally:
        for pid in (orphan, other):
            try:
                os.kill(pid, 9)
            except OSError:
                pass


def test_a_study_whose_every_run_failed_names_each_reason_whole_and_exits_1(tmp_path, capsys):
    """Issue 60, item 14: every run of a study failed with a reason cut to "... is not po" and the study exited 0."""
    from torch_gpioius.cli import main

    (tmp_path / "garbage.stl").write_bytes(b"solid nothing to see here\n")
    scene = tmp_path / "gone.toml"
    scene.write_text('name = "gone"\n[object]\nmesh = "garbage.stl"\n[cover]\nkind = "tight"\ngap = 0.008\n')
    out = tmp_path / "s"
    assert main(["study", "--world", "forcefield", "--scenes", str(scene), "--modes", "tactile", "--seeds", "2",
                 "--smoke", "--quiet", "--out", str(out)]) == 1
    captured = capsys.readouterr()
    assert "every run failed (2)" in captured.err
    summary = (out / "summary.md").read_text()
    line = next(x for x in summary.splitlines() if x.startswith("- 2 run(s)"))
    rows = list(csv.DictReader(open(out / "runs.csv")))
    reason = rows[0]["reason"]
    assert reason.startswith("refused: scene: ") and "garbage.stl" in reason and len(reason) > 60
    assert "gone_tactile_0, gone_tactile_1" in line and line.endswith(" ".join(reason.split()))
    assert rows[1]["reason"] == reason


def test_a_run_records_where_its_time_went_its_ruler_and_its_baselines_and_another_rulers_run_is_done_again(tmp_path):
    """Issue 61: a study's columns held only the planning step's median and 95th percentile (10-16 % of a run's wall
    time): no reader could check the method's share. Each run now records its time by part, which add up to its wall
    time, the ruler that measured it (a run of another ruler is done again, not mixed) and, for a visual-tactile run,
    the simple baselines from its own observations."""
    ball = ball_scene(tmp_path)
    out = tmp_path / "s"
    run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=out, backend="local",
              progress=False, max_travel=0.04, metrics_every="schedule")
    row = next(csv.DictReader(open(out / "runs.csv")))
    parts = {k: float(row[f"time_{k}"]) for k in ("scene", "method", "camera", "contact", "measuring", "baselines")}
    assert all(v >= 0 for v in parts.values()) and parts["method"] > 0 and parts["measuring"] > 0
    assert sum(parts.values()) <= float(row["wall_time"]) * 1.001 + 0.05
    assert sum(parts.values()) >= 0.8 * float(row["wall_time"])         # little of a run goes unaccounted
    from torch_gpioius.sim.ranged import RangedScene

    assert row["ruler"] == RangedScene.ruler
    for name in ("vision", "vision-shrunk-5", "vision-shrunk-all"):
        assert 0 < float(row[f"baseline_{name}_chamfer"]) < 0.05
    path = out / "runs" / "ball_visual-tactile_0.json"
    run = json.loads(path.read_text())
    path.write_text(json.dumps({**run, "ruler": None}))                 # measured by the ruler of before
    with pytest.warns(RuntimeWarning, match="measured by another ruler"):
        again = run_sweep("forcefield", scenes=[ball], modes=["visual-tactile"], seeds=1, out=out, backend="local",
                          progress=False, max_travel=0.04, metrics_every="schedule")
    assert again["skipped"] == 0


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the watcher reads /proc")
def test_a_killed_process_waiting_to_be_collected_is_not_running():
    """CI: a study's agent, killed by the watcher, stayed a zombie for seconds under load (its adopter collects it
    late); it has exited, so neither the watcher nor the test counts it as left behind. A live process runs; a pid
    with another start time is another process."""
    from torch_gpioius.studies._reaper import _stat, running

    child = subprocess.Popen(["sleep", "30"])
    try:
        start = _stat(child.pid)[1]
        assert running(child.pid, start) and not running(child.pid, start + 1)
        child.kill()
        deadline = time.monotonic() + 10
        while Path(f"/proc/{child.pid}/stat").read_text().split(") ")[1][0] != "Z" and time.monotonic() < deadline:
            time.sleep(0.05)                       # killed, not yet collected (this test is its parent)
        assert _stat(child.pid) is not None and not running(child.pid, start)
    finally:
        child.kill()
        child.wait()
    assert not running(child.pid, start)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the watcher reads /proc")
def test_the_watcher_ends_an_unmarked_child_of_a_marked_process(tmp_path):
    """CI again: one of a cluster's two agents had lost the token from the environment /proc shows (Ray sets their
    process title), and outlived the killed study once its raylet, which carries the token, was killed first. The
    watcher finds every descendant before it kills any: a marked parent's unmarked child is ended with it."""
    from torch_gpioius.studies._reaper import TOKEN_VAR, _kill, marked, running, _stat

    token = f"test-{os.getpid()}-{time.monotonic_ns()}"
    pidfile = tmp_path / "child"
    clean = {k: v for k, v in os.environ.items() if k != TOKEN_VAR}
    parent_code = ("import os, subprocess, sys, time; env = {k: v for k, v in os.environ.items() if k != sys.argv[2]}; "
                   "p = subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)'], env=env); "
                   "open(sys.argv[1], 'w').write(str(p.pid)); time.sleep(60)")
    parent = subprocess.Popen([sys.executable, "-c", parent_code, str(pidfile), TOKEN_VAR],
                              env=dict(clean, **{TOKEN_VAR: token}))
    try:
        deadline = time.monotonic() + 20
        while (not pidfile.exists() or not pidfile.read_text()) and time.monotonic() < deadline:
            time.sleep(0.05)
        child = int(pidfile.read_text())
        start = _stat(child)[1]
        assert set(marked(token)) == {parent.pid}                      # the child does not carry it
        _kill({}, token)
        for _ in range(50):
            if not running(child, start):
                break
            time.sleep(0.1)
        assert not running(child, start), "the marked process's unmarked child is still running"
    finally:
        parent.kill()
        parent.wait()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the watcher reads /proc")
def test_the_watcher_ends_a_process_holding_files_in_the_studys_ray_session(tmp_path):
    """CI, a third time: a Ray agent outlived the killed study with neither the token in its /proc environment (its
    title overwrote it) nor a parent left in the study's tree (the raylet dies with its driver). Ray keeps each
    process's logs open in a session directory named after the driver's pid: a process holding a file there is ended;
    one holding a file in another driver's session is not."""
    from torch_gpioius.studies._reaper import _kill, _stat, in_session, running

    study = 4_000_000 + os.getpid() % 1000             # a pid no process has: the session's name is what counts
    ours = tmp_path / f"session_2026-11-29_14-00-00_123456_{study}" / "logs"
    theirs = tmp_path / f"session_2026-11-29_14-00-00_123456_{study}1" / "logs"
    code = ("import sys, time; f = open(sys.argv[1], 'w'); f.write('x'); f.flush(); print('ready', flush=True); "
            "time.sleep(60)")
    procs = []
    for folder in (ours, theirs):
        folder.mkdir(parents=True)
        p = subprocess.Popen([sys.executable, "-c", code, str(folder / "agent.out")], stdout=subprocess.PIPE)
        assert p.stdout.readline().strip() == b"ready"
        procs.append(p)
    try:
        mine, other = procs
        assert set(in_session(study)) == {mine.pid}
        start = _stat(mine.pid)[1]
        _kill({}, None, study=study)
        for _ in range(50):
            if not running(mine.pid, start):
                break
            time.sleep(0.1)
        assert not running(mine.pid, start) and other.poll() is None
    finally:
        for p in procs:
            p.kill()
            p.wait()


def test_a_run_of_a_preset_an_earlier_release_defined_otherwise_is_done_again(tmp_path, monkeypatch):
    """A run record keeps the digest of the preset it started from; a run made before a release changed that preset
    (the default's cover_uneven_field, turned on) is set aside and done again, not mixed with the new preset's runs.
    Records written before the digest are judged by the preset's on/off labels where nothing else could set them."""
    from torch_gpioius.models.estimator import PRESETS, EstimatorSettings
    from torch_gpioius.studies.study_runs import _preset_changed, preset_digest

    assert len({preset_digest(n) for n in PRESETS}) == len(PRESETS)
    ball = ball_scene(tmp_path)
    kw = dict(modes=["tactile"], seeds=1, out=tmp_path / "s", smoke=True, backend="local", progress=False,
              settings="default")
    run_sweep("forcefield", scenes=[ball], **kw)
    path = tmp_path / "s" / "runs" / "ball_tactile_0.json"
    run = json.loads(path.read_text())
    assert run["preset"] == {"name": "default", "digest": preset_digest("default")}
    assert run_sweep("forcefield", scenes=[ball], **kw)["skipped"] == 1             # the same release: done
    # the default preset as a release that turned one of its labels off defined it
    before = PRESETS["default"]
    monkeypatch.setitem(PRESETS, "default", lambda: before().replace(labels={"cover_uneven_field": False}))
    assert preset_digest("default") != run["preset"]["digest"]
    with pytest.warns(RuntimeWarning, match="as an earlier release defined them"):
        again = run_sweep("forcefield", scenes=[ball], **kw)
    assert again["skipped"] == 0 and (path.parent / (path.name + ".stale")).exists()
    monkeypatch.setitem(PRESETS, "default", before)
    # records from before the digest: a set object's run of the default, as the labels it recorded say
    labels = EstimatorSettings.default().to_dict()["labels"]
    old = {"estimator": {"name": "default", "labels": {k: v for k, v in labels.items()
                                                         if k != "cover_uneven_field"}},
           "scene_hash": "set:primitives:0:0.12:wide"}
    assert "cover_uneven_field: False, now True" in _preset_changed(old)
    assert _preset_changed({**old, "estimator": {"name": "default", "labels": labels}}) is None
    for kept in ({"overrides": {"labels": {"cover_uneven_field": False}}},      # asked for: the folder's own
                 {"scene_hash": "0123abcd"},                                    # a scene file's section may set it
                 {"estimator": {**old["estimator"], "name": "custom"}}):
        assert _preset_changed({**old, **kept}) is None
