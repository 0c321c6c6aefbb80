"""scripts/benchmark_table.py on runs.csv files written here: the distributions (median, quartiles, 90th
percentile), the pairing of visual-tactile and touch alone per object and seed, the goals judged and the worst
objects, recomputed by hand."""

import csv
from pathlib import Path

from tests.scriptfiles import ROOT, load_script


def _load():
    return load_script("benchmark_table")


def _study(folder: Path, chamfers_vt, chamfers_t, h25_vt, h25_t):
    folder.mkdir()
    keys = ["world", "object", "mode", "seed", "failed", "terminated", "final_chamfer", "final_fscore_5mm",
            "final_fscore_10mm", "final_bias", "hausdorff_25", "final_hausdorff", "final_correlation", "travel",
            "wall_time"]
    with open(folder / "runs.csv", "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        for i, (cv, ct, hv, ht) in enumerate(zip(chamfers_vt, chamfers_t, h25_vt, h25_t)):
            for mode, c, h in (("visual-tactile", cv, hv), ("tactile", ct, ht)):
                w.writerow(dict(world="forcefield", object=f"obj-{i}", mode=mode, seed=0, failed=0,
                                terminated="travel", final_chamfer=c, final_fscore_5mm=0.5,
                                final_fscore_10mm=0.95 if c < 0.006 else 0.7, final_bias=-0.001,
                                hausdorff_25=h, final_hausdorff=2 * c, final_correlation=0.9, travel=0.6,
                                wall_time=20.0))


def test_distributions_pairs_goals_and_the_worst_are_the_runs_own(tmp_path):
    bt = _load()
    vt = [0.003, 0.004, 0.005, 0.006, 0.020]
    t = [0.004, 0.006, 0.004, 0.009, 0.030]
    _study(tmp_path / "a", vt, t, h25_vt=[0.02, 0.02, 0.03, 0.02, 0.05], h25_t=[0.03, 0.03, 0.02, 0.03, 0.06])
    label, rows = bt.read_arm(f"tight={tmp_path / 'a'}")
    assert label == "tight" and len(rows) == 10
    table = bt.distribution_table({label: rows})
    # order statistics of 0.3, 0.4, 0.5, 0.6, 2.0 cm: the 3rd, 2nd, 4th and 5th values
    assert "| tight | visual-tactile | 5 | 0 | 0.50 [0.40, 0.60] 2.00 |" in table
    pair = bt.paired(rows, "hausdorff_25")
    assert pair["n"] == 5 and pair["ahead"] == 0.8 and abs(pair["median"] - (-0.01)) < 1e-12
    goals = bt.goals(label, rows, wide=False)
    assert "median Chamfer 0.50 cm" in goals[0] and "holds" not in goals[0]       # p90 2.00 cm > 1.2
    assert "on 80 % of 5 pairs" in goals[2] and goals[2].endswith("holds")
    assert bt.worst(rows, 1)[0].startswith("obj-4 (seed 0): Chamfer 2.00 cm")
    wide = bt.goals(label, rows, wide=True)[0]
    assert "-0.20 cm over 5 pairs" in wide and wide.endswith("holds")       # the median of -0.1, -0.2, 0.1, -0.3, -1
    board = bt.leaderboard({label: rows})
    assert board.splitlines()[2].startswith("| tight | visual-tactile | 5 | 0.50 |")


def test_bad_arms_are_named_and_an_arm_without_vision_is_not_judged(tmp_path):
    """Issue 60, items 11 and 21: a missing folder, an arm without a label or a folder without runs.csv crashed with
    a traceback; an arm without visual-tactile runs printed "median Chamfer nan cm -> fails"; an unknown --wide label
    was ignored; the worst objects' lines ended in a bare "travel"."""
    import subprocess
    import sys

    import pytest

    bt = _load()
    _study(tmp_path / "a", [0.003, 0.004], [0.004, 0.006], h25_vt=[0.02, 0.02], h25_t=[0.03, 0.03])
    (tmp_path / "empty").mkdir()
    for spec, match in ((str(tmp_path / "a"), "an arm is LABEL=FOLDER"), ("=" + str(tmp_path / "a"), "LABEL=FOLDER"),
                        (f"x={tmp_path / 'nowhere'}", "is not a folder"),
                        (f"x={tmp_path / 'empty'}", "holds no runs.csv")):
        with pytest.raises(bt.ArmError, match=match):
            bt.read_arm(spec)
    script = str(ROOT / "scripts" / "benchmark_table.py")
    done = subprocess.run([sys.executable, script, f"x={tmp_path / 'nowhere'}"], capture_output=True, text=True)
    assert done.returncode == 2 and "is not a folder" in done.stderr and "Traceback" not in done.stderr
    done = subprocess.run([sys.executable, script, f"tight={tmp_path / 'a'}", "--wide", "wdie"], capture_output=True,
                          text=True)
    assert done.returncode == 2 and "--wide: ['wdie'] name no arm" in done.stderr
    _, rows = bt.read_arm(f"tight={tmp_path / 'a'}")
    touch = [r for r in rows if r["mode"] == "tactile"]
    assert bt.goals("touch", touch, wide=False) == ["touch: no visual-tactile runs, so no goal of the benchmark is "
                                                    "judged (modes: tactile)"]
    assert bt.worst(rows, 1)[0].endswith("ended at its travel budget")


def test_the_baselines_stand_beside_the_method_and_the_best_of_them_is_paired_per_object(tmp_path):
    """Issue 61: every visual-tactile run's baseline columns become rows of their own (``baseline:<name>``), and the
    method is paired per object against each and against the best of them (touch alone included), recomputed here."""
    import csv

    bt = _load()
    rows = []
    for i, (vt, t, vision, shrunk) in enumerate(((0.3, 0.8, 1.0, 0.4), (0.5, 0.9, 1.2, 0.35), (0.4, 0.3, 1.1, 0.6))):
        rows.append({"object": f"o{i}", "seed": "0", "mode": "visual-tactile", "failed": "", "final_chamfer": vt / 100,
                     "baseline_vision_chamfer": vision / 100, "baseline_vision-shrunk-5_chamfer": shrunk / 100,
                     "baseline_vision_bias": 0.005, "baseline_vision-shrunk-5_bias": -0.001})
        rows.append({"object": f"o{i}", "seed": "0", "mode": "tactile", "failed": "", "final_chamfer": t / 100})
    path = tmp_path / "runs.csv"
    keys = sorted({k for r in rows for k in r})
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        w.writerows(rows)
    _, read = bt.read_arm(f"a={tmp_path}")
    full = bt.with_baselines(read)
    assert sorted({r["mode"] for r in full}) == ["baseline:vision", "baseline:vision-shrunk-5", "tactile",
                                                 "visual-tactile"]
    best = bt.best_baseline(full)
    # the best per object: shrunk 0.4 (o0, VT ahead), shrunk 0.35 (o1, VT behind), touch 0.3 (o2, VT behind)
    assert best["n"] == 3 and abs(best["ahead"] - 1 / 3) < 1e-12
    assert best["best"] == {"baseline:vision-shrunk-5": 2, "tactile": 1}
    assert abs(best["median"] - 0.001) < 1e-12                              # -0.1, +0.15, +0.1 cm
    vision = bt.paired(full, "final_chamfer", "baseline:vision")
    assert vision["n"] == 3 and vision["ahead"] == 1.0
    lines = bt.baseline_lines("a", full)
    assert lines[0].startswith("a: GPIOIS ahead of the best baseline on 33 % of 3 objects, paired")
