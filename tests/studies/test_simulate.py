"""Smoke version of the 2-D study (the full study is `make demo`; `-m slow` runs it here too)."""

import json

import pytest

import torch_gpioius as tg

from torch_gpioius.cli import main
from torch_gpioius.studies.simulate import FRACTIONS, check_claims, run_study


def test_cli_smoke_writes_figures_records_and_summary(tmp_path, capsys):
    assert main(["simulate", "--object", "all", "--smoke", "--quiet", "--out", str(tmp_path)]) == 0
    for name in (
        "fig4_A.png",
        "fig4_B.png",
        "fig4_C.png",
        "fig4_D.png",
        "fig5_similarity.png",
        "records.csv",
        "records.json",
        "summary.md",
        "summary.json",
    ):
        assert (tmp_path / name).stat().st_size > 0
    records = json.loads((tmp_path / "records.json").read_text())
    modes = {r["mode"] for r in records}
    assert modes == {"visual-tactile", "tactile"}
    assert {r["object"] for r in records} == {"A", "B", "C", "D"}
    assert "| D |" in capsys.readouterr().out
    # the summary says what its columns are and where the claims are judged (a user read "no" with no pointer)
    summary = (tmp_path / "summary.md").read_text()
    assert "docs/results.md" in summary and "one run" in summary
    assert "H 100 %" in summary and "tactile-only run's** final travel" in summary and "**own** end" in summary
    # the final estimates as SVG curves next to the figures
    assert (tmp_path / "curves" / "A_visual-tactile_inner.svg").stat().st_size > 0
    assert (tmp_path / "curves" / "A_tactile_inner.svg").stat().st_size > 0


def test_cli_bad_object_exits_nonzero():
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--object", "Z"])
    assert exc.value.code != 0


def test_the_claims_table_points_to_the_explanations():
    from torch_gpioius.studies.simulate import _markdown

    row = {f"{k}_{int(f * 100)}": 0.01 for k in ("H_vt", "H_t") for f in FRACTIONS}
    row.update({f"S_{int(f * 100)}": 0.9 for f in FRACTIONS}, object="A", steps_vt=1, steps_t=1, terminated_vt="x",
               terminated_t="x", travel_vt_m=1.0, travel_tactile_m=1.0, H_vt_final=0.01, H_t_final=0.01,
               Ht_vt_final=0.01, Ht_t_final=0.01, rho_final=0.5, S_final=0.5, median_step_s_vt=0.01,
               median_step_s_t=0.01)
    text = _markdown([row], [{"claim": "x", "measured": "y", "holds": False}])
    assert "docs/results.md explains each" in text and "holds on this run" in text


def test_check_claims_on_hand_made_rows():
    row = {f"{k}_{int(f * 100)}": 0.01 for k in ("H_vt", "H_t") for f in FRACTIONS}
    row.update({f"S_{int(f * 100)}": 0.9 for f in FRACTIONS})
    a = dict(row, object="A", H_vt_25=0.02, H_t_25=0.05, H_vt_final=0.01, H_t_final=0.01, S_final=0.9,
             S_early_max=0.9, S_late_mean=0.9)
    d = dict(row, object="D", H_vt_final=0.01, H_t_final=0.012, S_final=0.1, S_early_max=0.2, S_late_mean=0.1)
    claims = {c["claim"][:2]: c["holds"] for c in check_claims([a, d])}
    assert claims["1."] and claims["4."] and claims["5."] and claims["6."]
    a["H_vt_final"] = 0.05  # 5 cm: adverse
    assert not {c["claim"][:2]: c["holds"] for c in check_claims([a, d])}["5."]


@pytest.mark.slow
def test_full_study_reproduces_claims_1_and_6(tmp_path):
    result = run_study(out=tmp_path, progress=False)
    holds = {c["claim"][:2]: c["holds"] for c in result["claims"]}
    assert holds["1."] and holds["6."]


def test_cli_fit_and_replay_on_the_shipped_example(tmp_path):
    from pathlib import Path

    from torch_gpioius.cli import main

    data = Path(__file__).resolve().parents[2] / "data" / "example_2d.gpioius"
    assert main(["fit", str(data), "--out", str(tmp_path / "fit")]) == 0
    model = tg.load_checkpoint(tmp_path / "fit" / "model.pt")
    assert 0 < model.similarity < 2 and (tmp_path / "fit" / "fit.png").stat().st_size > 0
    assert main(["replay", str(data), "--out", str(tmp_path / "rep"), "--every", "20", "--quiet"]) == 0
    rows = (tmp_path / "rep" / "records.csv").read_text().splitlines()
    assert rows[0].startswith("step,") and len(rows) == 1 + 3          # steps 0, 20, 40
    import csv

    last = list(csv.DictReader(rows))[-1]
    full = tg.load_dataset(data, upto_step=int(last["step"])).to_model().fit()
    assert float(last["correlation"]) == pytest.approx(full.correlation, abs=1e-6)   # both measures recorded
    assert float(last["similarity"]) == pytest.approx(full.similarity, abs=1e-6)
    assert (tmp_path / "rep" / "transition.png").stat().st_size > 0


def test_cli_bad_input_is_one_line_and_nonzero(tmp_path, capsys):
    from torch_gpioius.cli import main

    bad = tmp_path / "bad.gpioius"
    bad.write_bytes(b"not a dataset")
    assert main(["fit", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gpioius: error:") and "bad.gpioius" in err and "\n" not in err
    assert main(["replay", str(tmp_path / "missing.gpioius")]) == 2
