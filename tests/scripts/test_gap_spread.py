"""scripts/gap_spread.py: the touches' gaps replayed from a study log, against a by-hand recomputation and the truth
of a ball under a cover standing off it evenly."""

import numpy as np
import pytest

from tests.gaps import gaps_by_hand
from tests.scenes import SCENE
from tests.scriptfiles import load_script


def test_the_replay_reads_the_runs_gaps_and_the_covers_true_one(tmp_path, capsys):
    """A 6 cm ball under a cover 3.5 cm off it everywhere, one smoke run: the script's gaps at the end are the by-hand
    gaps' count, median and quartiles to rounding; it fires at the first contact where the by-hand median passes the
    limit (five counted at least); the true gap at the seen points is the cover's 3.5 cm, less the facets and the
    voxel means' chords (within 4 mm), and spread little (a cover grown evenly)."""
    import trimesh

    from torch_gpioius.io.datasets import contact_rows
    from torch_gpioius.io.runs import load_run
    from torch_gpioius.studies.study import run_sweep

    trimesh.creation.icosphere(3, 0.06).export(tmp_path / "ball.stl")
    scene = tmp_path / "ball.toml"
    scene.write_text(SCENE.format(name="ball", extra="").replace("gap = 0.008", "gap = 0.035"))
    run_sweep("forcefield", scenes=[scene], modes=["visual-tactile"], seeds=1, out=tmp_path / "s", smoke=True,
              backend="local", progress=False, max_travel=1.5)
    log = tmp_path / "s" / "logs" / "ball_visual-tactile_0.gpioius"
    spread = load_script("gap_spread")
    r = spread.replay(log, tmp_path, 0.03, None)

    run = load_run(log)
    final = run.states[run.steps[-1]]
    contacts = final.x[contact_rows(final.x, final.y, final.task)]
    seen = final.x[(final.task == 1) & (final.y == 0)]
    reach = max(0.02, float(run.meta.get("voxel_size") or run.meta.get("voxel") or 0.0))
    gaps = gaps_by_hand(contacts, seen, reach)
    assert len(gaps) >= 5 and r["contacts"] == len(contacts)
    n, med, p25, p75, rel = r["end"]
    assert n == len(gaps)
    np.testing.assert_allclose([med, p25, p75], np.percentile(gaps, [50, 25, 75]), atol=1e-12)
    assert rel == pytest.approx((p75 - p25) / med, rel=1e-12)
    fired = next((k for k in range(5, len(contacts) + 1)
                  if len(g := gaps_by_hand(contacts[:k], seen, reach)) >= 5 and np.median(g) > 0.03), None)
    assert r["fired"] == fired and fired is not None         # the 3.5 cm cover passes the 3 cm limit
    n_true, true_med, _, _, true_rel = r["true"]
    assert n_true > 20 and 0.031 < true_med < 0.039 and true_rel < 0.2
    spread.main([str(log), "--scenes", str(tmp_path)])
    assert "| ball_visual-tactile_0 |" in capsys.readouterr().out
