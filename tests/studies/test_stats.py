"""Failures count: a run with no estimate is the worst result in medians, intervals and paired comparisons, and
every table of a study shows how many runs failed and why."""

import json
import math

import numpy as np
import pytest
from scipy.stats import wilcoxon

from torch_gpioius.studies.stats import median_interval, paired_difference
from torch_gpioius.studies.study import aggregate, failure, failures_text


def test_a_missing_value_is_the_worst_value_not_a_dropped_one():
    values = [0.02, 0.03, 0.04, np.nan, np.nan]
    worst, dropped = median_interval(values), median_interval(values, failed="drop")
    # reference: the same statistic with the failures replaced by a value above every finite one
    big = median_interval([0.02, 0.03, 0.04, 1e9, 1e9])
    assert worst["median"] == big["median"] == 0.04 and worst["n"] == 5 and worst["failed"] == 2
    assert worst["lo"] == big["lo"] and worst["hi"] == math.inf and big["hi"] == 1e9
    # dropping them would report a better median over fewer runs: what the statistics must not do
    assert dropped["median"] == 0.03 < worst["median"] and dropped["n"] == 3 and dropped["failed"] == 2
    # an even count whose middle pair holds a failure has an infinite median (not NaN)
    assert median_interval([0.01, np.nan, np.nan, 0.02])["median"] == math.inf
    with pytest.raises(ValueError, match="failed"):
        median_interval(values, failed="ignore")


def test_a_pair_where_one_side_has_no_estimate_is_a_loss_for_that_side():
    a = np.array([0.01, np.nan, 0.03, np.nan, 0.02, 0.05])           # the mode
    b = np.array([0.02, 0.04, np.nan, np.nan, 0.03, 0.01])           # tactile
    d = paired_difference(a, b)
    assert d["n"] == 6 and d["failed"] == 3
    assert (d["wins"], d["losses"]) == (3, 2)           # seeds 0, 2 (tactile failed), 4 win; 1 (mode failed), 5 lose
    # the Wilcoxon test on the same ranks with the infinities replaced by large finite differences
    ref = np.array([-0.01, 10.0, -10.0, 0.0, -0.01, 0.04])
    assert d["p_wilcoxon"] == pytest.approx(wilcoxon(ref, zero_method="wilcox").pvalue)
    dropped = paired_difference(a, b, failed="drop")
    assert dropped["n"] == 3 and dropped["wins"] == 2
    with pytest.raises(ValueError, match="pair up"):
        paired_difference([1.0, 2.0], [1.0])


def _run(obj, mode, seed, hausdorff, terminated="travel", travel=1.5, budget=1.5):
    n = len(hausdorff)
    return {"world": "forcefield", "object": obj, "mode": mode, "seed": seed, "terminated": terminated,
            "steps": n - 1, "travel": travel, "budget": budget, "wall_time": 1.0, "median_step_time": 0.01, "taps": 0,
            "recoveries": 0, "contacts_on_body": math.nan, "contacts_within": 1.0,
            "series": {"travel": list(np.linspace(0, travel, n)), "hausdorff": hausdorff,
                       "hausdorff_touched": hausdorff, "uncertainty": [0.1] * n,
                       "similarity": [math.nan if mode == "tactile" else 1.0] * n,
                       "correlation": [math.nan if mode == "tactile" else 0.9] * n,
                       "correlation_lo": [math.nan] * n, "correlation_hi": [math.nan] * n}}


def test_failure_reasons():
    assert failure(_run("E", "tactile", 0, [0.1, 0.05])) == ""
    assert failure(_run("E", "tactile", 0, [math.nan, math.nan])) == "no estimate"
    assert failure(_run("E", "tactile", 0, [0.1, 0.05], terminated="stalled")) == "stalled"
    assert failure(_run("E", "tactile", 0, [0.1, 0.05], terminated="refused: force sensor overloaded on Fz")) \
        == "robot stop: overload"
    assert failure(_run("E", "tactile", 0, [0.1, 0.05], terminated="lost-contact")) == "lost contact"
    assert failure(_run("E", "tactile", 0, [0.1, 0.05], terminated="max_steps", travel=0.39)) == "step cap"
    assert failure(_run("E", "tactile", 0, [0.1, 0.05], terminated="max_steps", budget=None)) == ""
    assert failures_text(["", "stalled", "no estimate", "stalled"]) == "3: 1 no estimate, 2 stalled"
    assert failures_text(["", ""]) == "0"


def test_a_study_counts_its_failed_runs_in_every_table(tmp_path):
    runs = [_run("E", "visual-tactile", 0, [0.05, 0.02]), _run("E", "visual-tactile", 1, [math.nan, math.nan]),
            _run("E", "visual-tactile", 2, [0.05, 0.03], terminated="stalled", travel=0.4),
            _run("E", "tactile", 0, [0.2, 0.04]), _run("E", "tactile", 1, [0.2, 0.05]),
            _run("E", "tactile", 2, [0.2, 0.06])]
    (tmp_path / "runs").mkdir()
    for r in runs:
        (tmp_path / "runs" / f"{r['object']}_{r['mode']}_{r['seed']}.json").write_text(json.dumps(r))
    out = aggregate(tmp_path)
    vt = out["summary"]["objects"]["E"]["visual-tactile"]
    assert vt["n"] == 3 and vt["failed"] == 2 and vt["failures"] == "2: 1 no estimate, 1 stalled"
    assert vt["final_hausdorff"]["median"] == 0.03 and vt["final_hausdorff"]["hi"] == math.inf
    pair = out["summary"]["paired"]["E"]["visual-tactile"]["final_hausdorff"]
    assert pair["n"] == 3 and (pair["wins"], pair["losses"]) == (2, 1)
    table = (tmp_path / "summary.md").read_text()
    assert "| E | visual-tactile | 3 (75 %) | 2: 1 no estimate, 1 stalled |" in table
    assert "| E | tactile | 3 (75 %) | 0 |" in table
    rows = (tmp_path / "runs.csv").read_text().splitlines()
    assert rows[0].split(",")[4] == "failed" and sum("no estimate" in r for r in rows) == 1
