"""Smoke version of the 2-D study (the full study is `make demo`; `-m slow` runs it here too)."""

import json

import pytest

from torch_gpioius.cli import main
from torch_gpioius.study import FRACTIONS, check_claims, run_study


def test_cli_smoke_writes_figures_records_and_summary(tmp_path, capsys):
    assert main(["simulate", "--object", "all", "--smoke", "--quiet", "--out", str(tmp_path)]) == 0
    for name in ("fig4_A.png", "fig4_B.png", "fig4_C.png", "fig4_D.png", "fig5_similarity.png", "records.csv", "records.json", "summary.md", "summary.json"):
        assert (tmp_path / name).stat().st_size > 0
    records = json.loads((tmp_path / "records.json").read_text())
    modes = {r["mode"] for r in records}
    assert modes == {"visual-tactile", "tactile"}
    assert {r["object"] for r in records} == {"A", "B", "C", "D"}
    assert "| D |" in capsys.readouterr().out


def test_cli_bad_object_exits_nonzero():
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--object", "Z"])
    assert exc.value.code != 0


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
