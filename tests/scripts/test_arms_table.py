"""scripts/arms_table.py on a runs.csv written here: an arm's medians over seeds, a baseline scored beside the
visual-tactile runs read as an arm of its own, and the paired difference against the first arm, recomputed by hand."""

import csv
import sys
from pathlib import Path

import pytest

from tests.scriptfiles import load_script


def _load():
    return load_script("arms_table")


def _study(folder: Path) -> None:
    """Two objects, three seeds, both modes; the VT runs carry a baseline ``vision-shrunk-5``: seed 1 of obj-a's
    baseline gave no surface (empty cells)."""
    folder.mkdir()
    keys = ["object", "mode", "seed", "final_chamfer", "final_hausdorff", "final_fscore_10mm", "final_bias",
            "hausdorff_25", "baseline_vision-shrunk-5_chamfer", "baseline_vision-shrunk-5_hausdorff",
            "baseline_vision-shrunk-5_fscore_10mm", "baseline_vision-shrunk-5_fscore_5mm",
            "baseline_vision-shrunk-5_bias"]
    with open(folder / "runs.csv", "w", newline="") as f:
        w = csv.DictWriter(f, keys)
        w.writeheader()
        for obj, scale in (("obj-a", 1.0), ("obj-b", 2.0)):
            for seed in range(3):
                vt = scale * 0.003 * (seed + 1)
                w.writerow({"object": obj, "mode": "visual-tactile", "seed": seed, "final_chamfer": vt,
                            "final_hausdorff": 4 * vt, "final_fscore_10mm": 0.9, "final_bias": -0.001,
                            "hausdorff_25": 0.05,
                            "baseline_vision-shrunk-5_chamfer": "" if (obj, seed) == ("obj-a", 1) else vt + 0.001,
                            "baseline_vision-shrunk-5_hausdorff": 0.03, "baseline_vision-shrunk-5_fscore_10mm": 0.8,
                            "baseline_vision-shrunk-5_fscore_5mm": 0.6, "baseline_vision-shrunk-5_bias": 0.002})
                w.writerow({"object": obj, "mode": "tactile", "seed": seed, "final_chamfer": 0.01,
                            "final_hausdorff": 0.06, "final_fscore_10mm": 0.6, "final_bias": -0.005,
                            "hausdorff_25": 0.08})


def _table(module, capsys, monkeypatch, *arms):
    monkeypatch.setattr(sys, "argv", ["arms_table.py", *arms])
    module.main()
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("| obj-")]
    return {(ln.split(" | ")[0][2:], ln.split(" | ")[1]): ln.split(" | ") for ln in lines}


def test_a_baseline_is_an_arm_with_its_own_columns_and_pairs_by_seed(tmp_path, capsys, monkeypatch):
    at = _load()
    _study(tmp_path / "s")
    folder = str(tmp_path / "s")
    rows = _table(at, capsys, monkeypatch, f"vt={folder}", f"touch={folder}:tactile",
                  f"shrunk={folder}:baseline:vision-shrunk-5")
    header = ["object", "run"] + [c[0] for c in at.COLUMNS]
    chamfer = header.index("Chamfer final")
    # obj-a, VT: seeds 0.3, 0.6, 0.9 cm -> median 0.6; the baseline: 0.4, inf (no surface), 1.0 -> median 1.0
    assert rows[("obj-a", "vt (3)")][chamfer] == "0.60"
    assert rows[("obj-a", "shrunk (3)")][chamfer] == "1.00"
    assert rows[("obj-b", "shrunk (3)")][chamfer] == "1.30"          # 0.7, 1.3, 1.9
    assert rows[("obj-a", "touch (3)")][chamfer] == "1.00"
    # a baseline has no H at 25 % or correlation: '-', not a failure
    assert rows[("obj-a", "shrunk (3)")][header.index("H 25 %")] == "-"
    assert rows[("obj-a", "shrunk (3)")][header.index("H final")] == "3.0"
    assert rows[("obj-a", "shrunk (3)")][header.index("F@1cm final")] == "0.80"
    # paired against the first arm: +0.1 cm on the two seeds with a surface, +inf where it gave none
    assert rows[("obj-a", "shrunk (3)")][-1].startswith("0.10 (0 / 3)")


def test_an_arm_that_is_not_there_is_named(tmp_path, capsys, monkeypatch):
    at = _load()
    _study(tmp_path / "s")
    for spec, words in ((f"x={tmp_path / 'nowhere'}", "no "), (f"x={tmp_path / 's'}:baseline:vision-mirror",
                                                                "no baseline 'vision-mirror'"),
                        ("just-a-folder", "LABEL=FOLDER")):
        with pytest.raises(SystemExit, match=words):
            _table(at, capsys, monkeypatch, spec)
