"""scripts/worst_errors.py and scripts/claims_table.py's per-seed count, on a study run here."""

import csv
import math

import numpy as np
import pytest

from tests.scenes import ball_scene
from tests.scriptfiles import load_script

_load = load_script


def test_worst_errors_measure_the_run_as_the_study_did_and_place_the_worst_miss(tmp_path):
    """On a smoke study of a 6 cm ball: the script's Hausdorff distance is the study's own final one (the same
    world rebuilt from the record); the larger of its two exact worst distances lies within a sample spacing above
    that and two below it (the script and the study sample the same surfaces a spacing apart, each its own samples:
    a smoothed camera's run put the script's 1.5 um above the study's); the body's
    worst place lies in the body's box and on the ball, the estimate's as far from the sphere as reported; the
    nearest contact and seen point equal the ones recomputed from the log's final data."""
    from torch_gpioius.io.runs import load_run
    from torch_gpioius.studies.study import run_sweep

    # a smoke run's 40 steps over the world's own travel (a smoke run stops at 6 cm otherwise: too rough an estimate
    # for the worst places to be more than pieces of it)
    run_sweep("forcefield", scenes=[ball_scene(tmp_path)], modes=["visual-tactile"], seeds=1, out=tmp_path / "s",
              smoke=True, backend="local", progress=False, max_travel=1.5)
    row = next(csv.DictReader(open(tmp_path / "s" / "runs.csv")))
    log = tmp_path / "s" / "logs" / "ball_visual-tactile_0.gpioius"
    worst = _load("worst_errors")
    w = worst.worst_errors(log, tmp_path)
    assert w is not None
    assert w["hausdorff"] == pytest.approx(float(row["final_hausdorff"]), abs=1e-9)
    exact = [w["estimate->body"]["worst"], w["body->estimate"]["worst"]]
    assert max(exact) <= w["hausdorff"] + worst.SPACING
    assert max(exact) >= w["hausdorff"] - 2 * worst.SPACING
    box = w["body->estimate"]["box"]
    assert np.all(box >= -1e-9) and np.all(box <= 1 + 1e-9)
    for side in ("estimate->body", "body->estimate"):
        assert 0.0 <= w[side]["share"] <= 1.0 and math.isfinite(w[side]["touch"]) and math.isfinite(w[side]["camera"])
    # the nearest contact to the body's worst sample, recomputed from the log's final data
    run = load_run(log)
    data = run.states[run.steps[-1]]
    contacts = np.asarray(data.x)[(np.asarray(data.task) == 0) & (np.asarray(data.y) == 0)]
    seen = np.asarray(data.x)[(np.asarray(data.task) == 1) & (np.asarray(data.y) == 0)]
    world = worst.world_of(log, tmp_path)
    for side in ("estimate->body", "body->estimate"):
        p = w[side]["point"]
        assert w[side]["touch"] == pytest.approx(np.linalg.norm(contacts - p, axis=1).min(), abs=1e-12)
        assert w[side]["camera"] == pytest.approx(np.linalg.norm(seen - p, axis=1).min(), abs=1e-12)
    # the body's worst sample lies on the body (the ball's exact distance, within the mesh's facets), the
    # estimate's worst one as far from it as the script says (its exact distance to the sphere, 2 mm of facets)
    assert abs(world.true_distance(w["body->estimate"]["point"][None])[0]) < 1e-3
    centre = world.inner.bounds.mean(axis=0)
    off = abs(np.linalg.norm(w["estimate->body"]["point"] - centre) - 0.06)
    assert off == pytest.approx(w["estimate->body"]["worst"], abs=2e-3)
    text = worst.report(log, tmp_path, 0.02)
    assert text.startswith("ball_visual-tactile_0: H ") and "body->estimate worst" in text


def test_claims_table_counts_the_seeds_on_which_the_looser_cover_is_less_similar():
    """Paired by seed, only seeds both have with finite correlations; a difference within SEED_MARGIN (a K_t on the
    cone's boundary) is no difference."""
    claims = _load("claims_table")
    tight = {0: 1.0, 1: 1.0, 2: 0.9995, 3: 1.0, 4: math.nan}
    wide = {0: 0.95, 1: 1.0 - claims.SEED_MARGIN / 2, 2: 0.99, 4: 0.5, 5: 0.1}
    assert claims.seeds_lower(tight, wide) == (2, 3)
    assert claims.seeds_lower({}, wide) == (0, 0)


def test_camera_correction_refits_a_runs_contacts_with_its_captures_off_and_corrected(tmp_path, capsys, monkeypatch):
    """scripts/camera_correction.py on a smoke study's log: the four versions are fitted and measured, and the error
    at the body's middle is the applied one's (6 mm and a degree about cameras 0.35-1.1 m away: under 3 cm)."""
    import sys

    from torch_gpioius.studies.study import run_sweep

    run_sweep("forcefield", scenes=[ball_scene(tmp_path)], modes=["visual-tactile"], seeds=1, out=tmp_path / "s",
              smoke=True, backend="local", progress=False, max_travel=1.5)
    log = tmp_path / "s" / "logs" / "ball_visual-tactile_0.gpioius"
    script = _load("camera_correction")
    monkeypatch.setattr(sys, "argv", ["camera_correction.py", str(log), "--scenes", str(tmp_path)])
    script.main()
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("ball_visual-tactile_0 draw 0"))
    import re

    chamfer = re.findall(r"(calibrated|off|corrected|gap known) ([0-9.]+)", line.split(" cm |")[0])
    assert [n for n, _ in chamfer] == ["calibrated", "off", "corrected", "gap known"]
    assert all(0 < float(c) < 5 for _, c in chamfer)
    before = [float(v) for v in line.split("error at the body [")[1].split("]")[0].split(",")]
    assert len(before) == 3 and all(0 < b < 30 for b in before)       # [mm]: 6 mm and a degree, 0.35-1.1 m away
    assert "1 runs: median Chamfer calibrated" in out
