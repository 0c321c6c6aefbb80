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


def _under_a_flat_cover(gaps):
    """Seen points on a flat cover (z = 0, a 1 cm grid over 60 cm) and one contact under it per gap [m], 6 cm apart."""
    grid = np.arange(-0.3, 0.3001, 0.01)
    seen = np.stack(np.meshgrid(grid, grid), -1).reshape(-1, 2)
    seen = np.column_stack([seen, np.zeros(len(seen))])
    at = [(-0.24 + 0.06 * (i % 9), -0.24 + 0.06 * (i // 9)) for i in range(len(gaps))]
    return np.array([(x, y, -g) for (x, y), g in zip(at, gaps)]), seen


def _first_uneven(gaps, limit, even, held):
    """The contact count k (from five) at which the first k gaps first read uneven: past ``limit``, or one gap
    ``held``, and their interquartile range past ``even`` of their median (None: never)."""
    for k in range(5, len(gaps) + 1):
        g = np.asarray(gaps[:k])
        p25, med, p75 = np.percentile(g, [25, 50, 75])
        if (held or med > limit) and (p75 - p25) / med > even:
            return k
    return None


def test_the_replayed_rules_are_the_defaults_one_gap_its_field_or_retracted_at_once():
    """What the script says the default's gap rules did follows exploration.observations: touches that disagree from
    their first judgement retract at once (no gap, no field, whatever the count of places); touches that agree take
    one gap at the fifth contact and keep it, and once they stop agreeing it is judged (field or retracted) no sooner
    than FIELD_PLACES places. Gaps under a flat cover, so that each contact's gap is its depth (checked by hand)."""
    from torch_gpioius.exploration.observations import FIELD_PLACES
    from torch_gpioius.models.estimator import COVER_EVEN

    spread = load_script("gap_spread")
    limit = 0.03
    uneven = [0.01, 0.05, 0.02, 0.045, 0.035, 0.04, 0.015, 0.05, 0.03, 0.04]
    contacts, seen = _under_a_flat_cover(uneven)
    np.testing.assert_allclose(gaps_by_hand(contacts, seen, 0.02), uneven, atol=1e-12)
    _, taken = spread.field_taken(contacts, seen, 0.02, limit, COVER_EVEN)
    k = _first_uneven(uneven, limit, COVER_EVEN, held=False)
    assert k == 5 < FIELD_PLACES and taken == f"retracted {k}"        # at once, before the places a field needs

    even = [0.04] * 5 + [0.005] * 3 + [0.075] * 4
    contacts, seen = _under_a_flat_cover(even)
    _, taken = spread.field_taken(contacts, seen, 0.02, limit, COVER_EVEN)
    k = _first_uneven(even, limit, COVER_EVEN, held=True)
    assert k is not None and k < FIELD_PLACES                        # they stop agreeing before the field is judged
    assert taken in (f"gap 5, field {FIELD_PLACES}", f"gap 5, retracted {FIELD_PLACES}")

    contacts, seen = _under_a_flat_cover([0.04] * 12)
    assert spread.field_taken(contacts, seen, 0.02, limit, COVER_EVEN)[1] == "gap 5"
    contacts, seen = _under_a_flat_cover([0.01] * 12)
    assert spread.field_taken(contacts, seen, 0.02, limit, COVER_EVEN)[1] is None
