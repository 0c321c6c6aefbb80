"""Smoke version of the 3-D robot study (CI); the full study is `gpioius simulate3d` (`-m slow` runs it here)."""

import json

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.cli import main
from torch_gpioius.studies.simulate3d import check_claims_3d, run_study_3d


def test_cli_smoke_runs_the_loop_end_to_end(tmp_path, capsys):
    assert main(["simulate3d", "--object", "G", "--smoke", "--quiet", "--out", str(tmp_path)]) == 0
    for name in ("fig9_G.png", "fig10_similarity.png", "records.csv", "records.json", "summary.md",
                 "summary.json", "logs/G_visual-tactile.gpioius", "logs/G_tactile.gpioius"):
        assert (tmp_path / name).stat().st_size > 0, name
    records = json.loads((tmp_path / "records.json").read_text())
    assert {r["mode"] for r in records} == {"visual-tactile", "tactile"}
    assert all("contact_z" in r and "robot_time" in r for r in records)
    assert "| G |" in capsys.readouterr().out
    # issue 51, item 21: the 3-D summary says why each run ended (a MuJoCo run stopped on "lost-contact" after one
    # step said so only in summary.json)
    summary = (tmp_path / "summary.md").read_text()
    assert "steps (ended by)" in summary
    for r in json.loads((tmp_path / "summary.json").read_text())["rows"]:
        assert f"{r['steps_vt']} ({r['terminated_vt']}) / {r['steps_t']} ({r['terminated_t']})" in summary
    import trimesh

    mesh = trimesh.load(tmp_path / "meshes" / "G_visual-tactile_inner.ply")
    assert len(mesh.faces) > 0 and len(mesh.visual.vertex_colors) == len(mesh.vertices)
    # the logs replay: the training set of the last step has the inner contacts of the records
    ds = tg.load_dataset(tmp_path / "logs" / "G_tactile.gpioius")
    touched = ds.x[(ds.task == 0) & (ds.y == 0)]
    contacts = np.array([[r["contact_x"], r["contact_y"], r["contact_z"]] for r in records
                         if r["mode"] == "tactile"])
    np.testing.assert_allclose(touched, contacts)
    # issue 51, item 5: a re-run killed half-way left the new run's partial logs beside the old run's summary
    import torch_gpioius.studies.simulate3d as study3d

    before = {p.relative_to(tmp_path): p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()
              and p.name != ".lock"}
    real, calls = study3d.explore, []

    def killed_after_one_run(*args, **kw):
        if calls:
            raise KeyboardInterrupt
        calls.append(kw["log"])
        return real(*args, **kw)

    study3d.explore = killed_after_one_run
    try:
        assert main(["simulate3d", "--object", "G", "--smoke", "--quiet", "--out", str(tmp_path)]) == 130
    finally:
        study3d.explore = real
    assert calls and not str(calls[0]).startswith(str(tmp_path / "logs"))        # the new run wrote elsewhere
    after = {p.relative_to(tmp_path): p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()
             and p.name != ".lock"}
    assert after == before                        # the old run whole: its logs, records and summary, nothing else


def test_check_claims_on_hand_made_rows():
    base = {f"{k}_{f}": 0.02 for k in ("H_vt", "H_t") for f in (10, 50, 100)}
    base.update({f"U_{k}_100": 0.1 for k in ("vt", "t")})
    e = dict(base, object="E", H_t_10=0.15, H_vt_10=0.02, S_mean=0.9)
    f = dict(base, object="F", H_vt_10=0.05, H_vt_100=0.02, S_mean=0.7)
    h = dict(base, object="H", H_vt_100=0.10, H_t_100=0.11, S_mean=0.3)
    holds = {c["claim"][:2]: c["holds"] for c in check_claims_3d([e, f, h])}
    assert holds == {"E ": True, "F ": True, "H ": True, "Fi": True}
    e["H_vt_10"] = 0.12                         # vision did not help at the start
    h["S_mean"] = 1.0                           # H is no longer the least similar
    holds = {c["claim"][:2]: c["holds"] for c in check_claims_3d([e, f, h])}
    assert not holds["E "] and not holds["Fi"]


def test_unknown_object():
    with pytest.raises(ValueError, match="unknown"):
        run_study_3d(["Q"], progress=False)


@pytest.mark.slow
def test_full_study_runs(tmp_path):
    result = run_study_3d(out=tmp_path, progress=False)
    assert {r["object"] for r in result["rows"]} == {"E", "F", "G", "H"}
    assert all(tr.terminated == "travel" for pair in result["traces"].values() for tr in pair.values())


def test_cli_smoke_runs_the_mujoco_study(tmp_path, capsys):
    """`gpioius simulate3d --world mujoco --smoke`: the MuJoCo study end to end in its CI form (coarse cloth, a
    quarter-resolution camera, 6 cm of travel): records, logs, figures and meshes as in the force-field world."""
    pytest.importorskip("mujoco")
    assert main(["simulate3d", "--world", "mujoco", "--object", "E", "--smoke", "--quiet", "--out",
                 str(tmp_path)]) == 0
    for name in ("fig9_E.png", "fig10_similarity.png", "records.csv", "summary.md", "logs/E_visual-tactile.gpioius",
                 "logs/E_tactile.gpioius"):
        assert (tmp_path / name).stat().st_size > 0, name
    records = json.loads((tmp_path / "records.json").read_text())
    assert {r["mode"] for r in records} == {"visual-tactile", "tactile"}
    travel = max(r["travel"] for r in records)
    assert 0.05 < travel < 0.2                                   # the smoke budget, not the study's 1.5 m
    assert "| E |" in capsys.readouterr().out


def _trace(mode, hausdorff, estimate, shape=None):
    from torch_gpioius.exploration import Trace

    n = len(hausdorff)
    return Trace(mode=mode, scene_name="box", hausdorff=np.array(hausdorff, float), uncertainty=np.full(n, 0.1),
                 similarity=np.full(n, 0.5), travel=np.linspace(0, 0.6, n), path=np.zeros((0, 3)),
                 contacts=np.zeros((n, 3)), model=None, step_time=np.full(n, 0.01), terminated="travel",
                 robot_time=np.arange(n, dtype=float), estimate=np.array(estimate, float),
                 shape={k: np.full(n, v) for k, v in (shape or {}).items()})


def test_the_summary_names_runs_without_an_estimate_and_counts_valid_samples():
    """Issue 33, item 5: "8.3 / 8.3 / 8.3" was printed when 4 of 6 samples were NaN, and "nan" said nothing."""
    from torch_gpioius.studies.simulate3d import _markdown, summarize_3d

    nan = np.nan
    vt = _trace("visual-tactile", [0.083, nan, nan, nan, nan, nan, 0.083], [1, 0, nan, 0, 0, 0, 1])
    t = _trace("tactile", [0.09, nan, nan, 0.07, nan, nan, nan], [1, nan, nan, 1, nan, nan, 0])
    rows = summarize_3d({"box": {"visual-tactile": vt, "tactile": t}}, {"box": 0.01})
    r = rows[0]
    assert np.isnan(r["H_vt_10"])               # the sample at 10 % had no surface: no later value stands in
    assert (r["valid_vt"], r["measured_vt"]) == (2, 6) and (r["valid_t"], r["measured_t"]) == (2, 3)
    assert r["estimate_vt"] is True and r["estimate_t"] is False
    text = _markdown(rows, None)
    assert "| none / " in text and "2 of 6 / 2 of 3" in text
    assert "**No estimate at the end:** box tactile" in text and "Columns: H is the Hausdorff distance" in text
    assert "| 0.60 (0: 0.00 m) / 0.60 (0: 0.00 m) |" in text                # travel and its re-approaches


def test_claims_are_not_judged_on_runs_that_barely_explored():
    """Issue 33, item 9: `--max-travel 1e-9` marked the claims "yes" after one step, `--max-steps 0` marked them
    "no"; below a stated minimum they are "not judged"."""
    from torch_gpioius.studies import simulate as study2d, simulate3d as study3d

    short = _trace("visual-tactile", [0.05, 0.04], [1, 1])                    # 2 records: 1 step, 0.6 m
    why = study3d.explored_enough({"E": {"visual-tactile": short}})
    assert why and "E visual-tactile (0.6 m, 1 steps)" in why
    text = study3d._markdown(study3d.summarize_3d({"E": {"visual-tactile": short}}, {}), None, why)
    assert "The paper's claims are not judged: runs below 0.3 m of travel or 10 steps" in text
    long = _trace("visual-tactile", [0.05] * 30, [1] * 30)
    assert study3d.explored_enough({"E": {"visual-tactile": long}}) is None
    none = _trace("tactile", [0.05], [1])                                     # --max-steps 0: record 0 only
    assert "A tactile (0)" in study2d.explored_enough({"A": {"tactile": none, "visual-tactile": long}})
    assert study2d.explored_enough({"A": {"visual-tactile": long}}) is None


def test_a_summary_of_scene_files_has_no_empty_claims_table():
    """Issue 35, item 18: scene files gave an empty claims table."""
    from torch_gpioius.studies.simulate3d import _markdown, check_claims_3d, summarize_3d

    long = _trace("visual-tactile", [0.05] * 30, [1] * 30)
    rows = summarize_3d({"bunny": {"visual-tactile": long, "tactile": long}}, {})
    claims = check_claims_3d(rows)
    text = _markdown(rows, claims)
    assert claims == [] and "| claim (Sec. VI-B)" not in text and "none of them ran here" in text


def test_the_summary_shows_the_fields_metrics_at_the_end():
    """Issue 34, item 5: Chamfer, F-score, bias and the unseen share beside H in simulate3d's summary."""
    from torch_gpioius.studies.simulate3d import _markdown, summarize_3d

    vt = _trace("visual-tactile", [0.05] * 3, [1] * 3, {"chamfer": 0.012, "fscore_5mm": 0.31, "bias": -0.011,
                                                        "unseen": 0.25})
    t = _trace("tactile", [0.05] * 3, [1] * 3)
    text = _markdown(summarize_3d({"box": {"visual-tactile": vt, "tactile": t}}, {}), None)
    assert "| Chamfer VT / T [cm] | F 5 mm VT / T | bias VT / T [cm] | unseen VT / T |" in text
    assert "| 1.2 / - | 0.31 / - | -1.1 / - | 0.25 / - |" in text
