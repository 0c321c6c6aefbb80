"""A study's aggregation (:mod:`.sweep`): one row per run (``runs.csv``), the per-object and per-mode statistics
(``summary.json``: medians with 95 % intervals, paired differences), the paper's claims judged with stated rules, and
``summary.md``."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from ..geometry.metrics import SHAPE_METRICS
from .stats import median_interval, paired_difference
from ..baselines import BASELINE_METRICS, BASELINES
from .study_runs import FRACTIONS, RunSpec, read_run_file

#: The parts of a run's wall time a run file records (``time`` of :func:`~torch_gpioius.studies.study.run_one`).
TIME_PARTS = ("scene", "method", "camera", "contact", "measuring", "baselines")

__all__ = ["aggregate", "failure", "failures_text", "failed_runs", "no_harm_margin", "METRICS",
           "NOT_APPLICABLE_METRICS", "MIN_SEEDS_TO_JUDGE"]

def _last_finite(v) -> float:
    v = np.asarray(v, dtype=float)
    ok = np.flatnonzero(np.isfinite(v))
    return float(v[ok[-1]]) if len(ok) else math.nan


def _at_travel(series: dict, key: str, distance: float) -> float:
    """The value of the first measured record at or after ``distance`` of travel (NaN where that estimate had no
    surface: a later step's value never stands in for it); the final record's if the run ended before. Run files
    without the ``estimate`` series: the first finite value, as they were read then."""
    t = np.asarray(series["travel"], dtype=float)
    v = np.asarray(series[key], dtype=float)
    est = series.get("estimate")
    if est:
        measured = ~np.isnan(np.asarray(est, dtype=float))
        ok = np.flatnonzero(measured & (t >= distance - 1e-12))
        return float(v[ok[0]] if len(ok) else v[-1])
    ok = np.flatnonzero(np.isfinite(v) & (t >= distance - 1e-12))
    if len(ok):
        return float(v[ok[0]])
    return _last_finite(v)


def _reference_travel(run: dict, runs_by_key: dict) -> float:
    """The travel budget of a budgeted run (the robot study); else the tactile run of the same object and seed (the
    paper's 2-D table), or the run's own travel."""
    if run.get("budget"):
        return float(run["budget"])
    tactile = runs_by_key.get((run["object"], "tactile", run["seed"]))
    return float((tactile or run)["travel"])


def failure(run: dict) -> str:
    """Why a run failed, or "" if it did not: "stalled" (the no-progress rule gave up), "scene: <why>" (its world
    could not be built: :data:`_SCENE_REASONS`), "approach: <why>" (no first
    contact: the approach missed the body or the robot refused it), "robot stop: <why>" (the
    safety layer or the contact controller stopped the robot before the run's own end), "lost contact", "step cap"
    (the step budget ran out before the travel budget) or "no estimate" (no estimated surface inside the range at
    the end). A failed run stays in every statistic (see :mod:`torch_gpioius.studies.stats`)."""
    t = run["terminated"]
    if t == "stalled":
        return "stalled"
    if t.startswith("refused: scene"):
        return "scene: " + _scene_reason(t[len("refused: scene"):].lstrip(": "))
    if t.startswith("refused: approach"):
        return "approach: " + _short_reason(t[len("refused: approach"):].lstrip(": "))
    if t.startswith("refused"):
        return "robot stop: " + _short_reason(t[len("refused"):].lstrip(": "))
    if t == "lost-contact":
        return "lost contact"
    if t == "max_steps" and run.get("budget") and run["travel"] < 0.999 * run["budget"]:
        return "step cap"
    if not _has_final_estimate(run):
        return "no estimate"
    return ""


def _has_final_estimate(run: dict) -> bool:
    """Whether the run's final estimate has a surface to judge: its last record says so where it was recorded
    (runs since the ``estimate`` series); older run files: some Hausdorff distance was measured."""
    est = run["series"].get("estimate")
    if est:
        return not est[-1] == 0.0
    return math.isfinite(_last_finite(run["series"]["hausdorff"]))


def _final(run: dict, key: str) -> float:
    """A metric of the final estimate: the last record's value (always measured; NaN when the run ended with no
    estimate, never an earlier step's value). Older run files without the ``estimate`` series: the last measured
    value, as they were read then."""
    s = run["series"]
    if s.get("estimate"):
        return float(s[key][-1]) if _has_final_estimate(run) else math.nan
    return _last_finite(s[key])


#: A refused scene's message, by what it says, in a few words for counting (the message begins with the object's
#: name and file, which the first 60 characters, kept before, were mostly made of).
_SCENE_REASONS = (("nowhere more than", "too thin to feel"), ("max_repair_distance", "repair moves the surface"),
                  ("only grazes", "approach grazes"), ("no downward ray", "approach misses"),
                  ("no extent", "mesh has no extent"), ("probably in millimetres", "wrong units"),
                  ("not closed", "mesh not closed"), ("no such file", "unreadable mesh"),
                  ("cannot read", "unreadable mesh"), ("could not read", "unreadable mesh"),
                  ("must contain the inner", "cover does not contain the body"))


def _scene_reason(why: str) -> str:
    """A refused scene's message in a few words (:data:`_SCENE_REASONS`); otherwise what follows the object's name
    and file, cut to 40 characters."""
    low = why.lower()
    for key, label in _SCENE_REASONS:
        if key in low:
            return label
    return why.rsplit("): ", 1)[-1][:40] or "refused"


def _short_reason(why: str) -> str:
    """A robot stop's message in a few words for a table cell."""
    low = why.lower()
    for key, label in (("did not follow", "arm stuck"), ("found no contact", "no contact"), ("overload", "overload"),
                       ("inverse kinematics", "IK refused"), ("ik ", "IK refused"), ("joint speed", "joint speed"),
                       ("joint limit", "joint limit"), ("workspace", "workspace"), ("force", "force limit"),
                       ("timeout", "sensor timeout"), ("stale", "sensor stale")):
        if key in low:
            return label
    return why[:40] or "refused"


def failures_text(reasons) -> str:
    """``"0"`` or ``"2: 1 stalled, 1 no estimate"`` from the runs' :func:`failure` reasons."""
    from collections import Counter

    counts = Counter(r for r in reasons if r)
    if not counts:
        return "0"
    return f"{sum(counts.values())}: " + ", ".join(f"{n} {why}" for why, n in sorted(counts.items()))


def _row(run: dict, runs_by_key: dict) -> dict:
    s = run["series"]
    ref = _reference_travel(run, runs_by_key)
    row = {"world": run["world"], "object": run["object"], "mode": run["mode"], "seed": run["seed"],
           "failed": failure(run),
           # how the run ended, whole (the failed column is its cause in a few words, for counting)
           "reason": run["terminated"],
           "final_hausdorff": _final(run, "hausdorff"),
           "final_hausdorff_touched": _final(run, "hausdorff_touched"),
           "final_uncertainty": _final(run, "uncertainty"),
           **{f"final_{k}": _final(run, k) if k in s else math.nan for k in SHAPE_METRICS},
           # no estimate: no estimated surface agrees with the truth at any distance
           **({f"final_{k}": 0.0 for k in SHAPE_METRICS if k.startswith("fscore")}
              if "fscore_5mm" in s and not _has_final_estimate(run) else {}),
           "final_correlation": _last_finite(s["correlation"]),
           "final_correlation_lo": _last_finite(s["correlation_lo"]),
           "final_correlation_hi": _last_finite(s["correlation_hi"]),
           "final_similarity": _last_finite(s["similarity"]),
           "travel": run["travel"], "steps": run["steps"], "terminated": run["terminated"], "taps": run["taps"],
           "recoveries": run["recoveries"], "reapproaches": run.get("reapproaches", 0),
           "reapproach_share": run.get("reapproach_travel", 0.0) / run["travel"] if run["travel"] > 0 else 0.0,
           "has_estimate": _has_final_estimate(run),
           "contacts_on_body": run["contacts_on_body"],
           "contacts_within": run["contacts_within"],
           "wall_time": run["wall_time"], "median_step_time": run["median_step_time"],
           # where the run's time went [s] (runs before the split was recorded: NaN)
           **{f"time_{k}": run.get("time", {}).get(k, math.nan) for k in TIME_PARTS},
           "ruler": run.get("ruler") or "",
           # the simple baselines from the same observations (visual-tactile runs; torch_gpioius.baselines)
           **{f"baseline_{name}_{k}": run.get("baselines", {}).get(name, {}).get(k, math.nan)
              for name in BASELINES.names() for k in BASELINE_METRICS},
           # older run files have the median alone
           "p95_step_time": run.get("p95_step_time", math.nan), "max_step_time": run.get("max_step_time", math.nan),
           "reference_travel": ref,
           # the travel budget the run was asked for [m] (empty: none, the 2-D world's once around)
           "budget": run.get("budget") if run.get("budget") is not None else math.nan,
           "voxel": run.get("voxel", math.nan), "n_outer": run.get("n_outer", math.nan),
           "touch_inside": run.get("touch_inside", 0.0), "vision_inside": run.get("vision_inside", 0.0),
           "vision_inside_gap": run.get("vision_inside_gap", 0.0),
           "n_vision_inside": run.get("n_vision_inside", math.nan),
           # the outer task's prior mean at the end (runs before 2026-11-27: the paper's 1; touch alone: NaN)
           "final_outer_mean": run.get("outer_mean", 1.0 if run["mode"] != "tactile" else math.nan),
           "max_truncation": run.get("max_truncation", 0.0), "max_fit_gap": run.get("max_fit_gap", math.nan),
           # what the run learned (older runs: K_t alone, length and noise not recorded)
           "learn": run.get("learn", "task"), "final_length": run.get("length", math.nan),
           "final_noise": run.get("noise", math.nan)}
    for f in FRACTIONS:
        p = int(round(100 * f))
        row[f"hausdorff_{p}"] = _at_travel(s, "hausdorff", f * ref)
        row[f"uncertainty_{p}"] = _at_travel(s, "uncertainty", f * ref)
        for k in ("chamfer", "fscore_5mm", "bias", "unseen"):
            row[f"{k}_{p}"] = _at_travel(s, k, f * ref) if k in s else math.nan
    return row


def aggregate(out: str | Path, specs: list[RunSpec] | None = None, smoke: bool = False, world: str | None = None,
              max_travel: float | None = None) -> dict:
    """Read the run files of ``out`` (those of ``specs``, or every finished run of ``world`` there: a folder
    accumulates runs, e.g. more modes or seeds later) and write runs.csv, summary.json/md and figures."""
    out = Path(out)
    paths = ([out / "runs" / f"{s.key}.json" for s in specs] if specs is not None
             else sorted((out / "runs").glob("*.json")))
    runs = [read_run_file(p) for p in paths if p.exists()]
    if world is not None:
        runs = [r for r in runs if r["world"] == world]
    if not runs:
        raise ValueError(f"{out}: no finished runs to aggregate")
    by_key = {(r["object"], r["mode"], r["seed"]): r for r in runs}
    rows = sorted((_row(r, by_key) for r in runs), key=lambda x: (x["object"], x["mode"], x["seed"]))
    fields = list(rows[0])
    with open(out / "runs.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    summary = _summarize(rows)
    summary["failed_runs"] = failed_runs(rows)
    claims = None if smoke else _claims(summary)
    (out / "summary.json").write_text(json.dumps({**summary, "claims": claims}, indent=1, allow_nan=True))
    (out / "summary.md").write_text(_markdown(rows[0]["world"], summary, claims, len(rows)))
    from .study_figures import figure_paired, figure_similarity_bands, figure_transition_bands

    for obj in sorted({r["object"] for r in runs}):
        figure_transition_bands(obj, [r for r in runs if r["object"] == obj], out / f"transitions_{obj}.png")
    figure_similarity_bands(runs, out / "similarity_bands.png")
    figure_paired(rows, out / "paired_final_hausdorff.png")
    if any(math.isfinite(r.get("final_chamfer", math.nan)) for r in rows):      # 3-D worlds and the 2-D one alike
        figure_paired(rows, out / "paired_final_chamfer.png", key="final_chamfer")
    return {"rows": rows, "summary": summary, "claims": claims}


METRICS = ["final_hausdorff", "final_hausdorff_touched", "final_uncertainty", "final_correlation",
           "final_similarity"] + [f"hausdorff_{int(round(100 * f))}" for f in FRACTIONS] + [
    "final_chamfer", "final_fscore_1mm", "final_fscore_5mm", "final_fscore_10mm", "final_fscore_20mm", "final_bias",
    "final_hausdorff_observed", "final_unseen", "chamfer_25", "fscore_5mm_25"]
#: Metrics where NaN means "the mode has no such value" (a tactile run has no correlation), not a failure; every
#: other metric is a distance or a variance, where NaN is "no estimate" and counts as the worst value.
NOT_APPLICABLE_METRICS = ("final_correlation", "final_similarity", "contacts_on_body", "contacts_within",
                          # a higher F-score is better (a run with no estimate has 0, set in its row), the bias is
                          # signed, the unseen share is not an error: NaN there is "not measured" (older runs)
                          "final_fscore_1mm", "final_fscore_5mm", "final_fscore_10mm", "final_fscore_20mm",
                          "final_bias", "final_unseen", "fscore_5mm_25")


def _policy(metric: str) -> str:
    return "drop" if metric in NOT_APPLICABLE_METRICS else "worst"


def _summarize(rows: list[dict]) -> dict:
    """``{object: {mode: {metric: median_interval, "n": runs}}}`` and paired VT - T differences per object."""
    out: dict = {"objects": {}, "paired": {}}
    objects = sorted({r["object"] for r in rows})
    modes = sorted({r["mode"] for r in rows})
    for obj in objects:
        out["objects"][obj] = {}
        for mode in modes:
            rs = [r for r in rows if r["object"] == obj and r["mode"] == mode]
            if not rs:
                continue
            entry = {m: median_interval([r[m] for r in rs], failed=_policy(m)) for m in METRICS}
            entry["n"] = len(rs)
            entry["failed"] = sum(bool(r["failed"]) for r in rs)
            entry["failures"] = failures_text(r["failed"] for r in rs)
            for m in ("taps", "travel", "recoveries", "reapproaches", "reapproach_share", "contacts_on_body",
                      "contacts_within"):
                entry[m] = median_interval([r[m] for r in rs], failed="drop")
            out["objects"][obj][mode] = entry
        tactile = {r["seed"]: r for r in rows if r["object"] == obj and r["mode"] == "tactile"}
        for mode in modes:
            if mode == "tactile":
                continue
            other = {r["seed"]: r for r in rows if r["object"] == obj and r["mode"] == mode}
            seeds = sorted(set(tactile) & set(other))
            if not seeds:
                continue
            out["paired"].setdefault(obj, {})[mode] = {
                m: paired_difference([other[s][m] for s in seeds], [tactile[s][m] for s in seeds], failed="worst")
                for m in ("final_hausdorff", "hausdorff_10", "hausdorff_25", "hausdorff_50")}
    return out


# ---------------------------------------------------------------------------------------------- claims
def _cm(v: float) -> str:
    return "n/a" if math.isnan(v) else ("inf" if math.isinf(v) else f"{100 * v:.1f}")


def no_harm_margin(t: dict) -> float:
    """The "no harm" margin [m] of a tactile-only :func:`~torch_gpioius.studies.stats.median_interval` ``t``: 10 % of
    its median, at least 0.5 cm (0.5 cm where tactile-only failed)."""
    return max(0.1 * t["median"], 0.005) if math.isfinite(t["median"]) else 0.005


def _no_harm(summary: dict, obj: str, mode: str = "visual-tactile") -> tuple[bool | None, str]:
    """"No harm": the upper end of the 95 % interval of the median paired difference VT - T of the final Hausdorff
    distance is at most max(10 % of the median tactile value, 0.5 cm)."""
    pair = summary["paired"].get(obj, {}).get(mode, {}).get("final_hausdorff")
    t = summary["objects"][obj].get("tactile", {}).get("final_hausdorff")
    if pair is None or t is None or pair["n"] == 0:
        return None, "no paired runs"
    allowed = no_harm_margin(t)
    return bool(pair["hi"] <= allowed), (f"median VT - T {_cm(pair['median'])} cm, 95 % interval [{_cm(pair['lo'])}, "
                                         f"{_cm(pair['hi'])}] cm (allowed {_cm(allowed)} cm), Wilcoxon p = "
                                         f"{pair['p_wilcoxon']:.3g}, n = {pair['n']}")


def _early_benefit(summary: dict, obj: str, key: str, mode: str = "visual-tactile") -> tuple[bool | None, str]:
    """"Accurate from the beginning": at the given point of travel the 95 % interval of the median paired
    difference VT - T lies below 0, and the median visual-tactile distance is at most half the tactile one."""
    pair = summary["paired"].get(obj, {}).get(mode, {}).get(key)
    vt = summary["objects"][obj].get(mode, {}).get(key)
    t = summary["objects"][obj].get("tactile", {}).get(key)
    if pair is None or vt is None or t is None:
        return None, "no paired runs"
    holds = pair["hi"] < 0 and vt["median"] <= 0.5 * t["median"]
    return bool(holds), (f"VT {_cm(vt['median'])} [{_cm(vt['lo'])}, {_cm(vt['hi'])}] cm vs T {_cm(t['median'])} "
                         f"[{_cm(t['lo'])}, {_cm(t['hi'])}] cm; paired VT - T {_cm(pair['median'])} "
                         f"[{_cm(pair['lo'])}, {_cm(pair['hi'])}] cm, p = {pair['p_wilcoxon']:.3g}")


#: The fewest seeds per object and mode on which a claim is judged: with n seeds the order-statistic interval of a
#: median covers at most 1 - 2^(1-n) (93.75 % at 5, 96.9 % at 6) and the smallest two-sided Wilcoxon p is 2^(1-n); a
#: study of 2 seeds judged "holds: yes" beside its own table's 50 % coverage and p = 0.5.
MIN_SEEDS_TO_JUDGE = 6


def _claims(summary: dict) -> list[dict]:
    """The paper's claims about the objects present (A-D: Sec. V; E-H: Sec. VI), each judged by a stated rule."""
    objs = summary["objects"]
    claims = []
    seeds = min((e["n"] for modes in objs.values() for e in modes.values()), default=0)
    too_few = seeds < MIN_SEEDS_TO_JUDGE

    def add(claim: str, rule: str, result: tuple[bool | None, str]) -> None:
        holds, measured = result
        if too_few:          # a 95 % interval needs 6 seeds: fewer cannot hold or fail a claim
            holds, measured = None, (f"too few seeds to judge ({seeds}; a 95 % interval of a median and a Wilcoxon "
                                     f"p below 0.05 need {MIN_SEEDS_TO_JUDGE}): {measured}")
        claims.append({"claim": claim, "rule": rule, "holds": holds, "measured": measured})

    rule_early = ("95 % interval of the median paired VT - T below 0 and median VT <= half median T")
    rule_harm = ("upper end of the 95 % interval of the median paired VT - T (final) <= max(10 % of median T, 0.5 cm)")
    # Sec. V, objects A-D
    if "A" in objs:
        add("A: visual-tactile close to the inner shape from the beginning (25 % of travel)", rule_early,
            _early_benefit(summary, "A", "hausdorff_25"))
    if "B" in objs:
        add("B: VT better early (10 % of travel)", rule_early, _early_benefit(summary, "B", "hausdorff_10"))
        add("B: about equal at the end", rule_harm + ", both ways",
            _equal(summary, "B"))
    if "D" in objs:
        add("D: both reach about the same final Hausdorff", rule_harm + ", both ways", _equal(summary, "D"))
    if "A" in objs and "D" in objs:
        a = objs["A"].get("visual-tactile", {}).get("final_correlation")
        d = objs["D"].get("visual-tactile", {}).get("final_correlation")
        if a and d:
            add("Final similarity A clearly above D (task correlation)", "95 % intervals of the medians disjoint, A "
                "above", (bool(a["lo"] > d["hi"]), f"A {a['median']:.2f} [{a['lo']:.2f}, {a['hi']:.2f}] vs D "
                          f"{d['median']:.2f} [{d['lo']:.2f}, {d['hi']:.2f}]"))
    # Sec. VI, objects E-H
    for obj in ("E", "G"):
        if obj in objs:
            add(f"{obj} (tight): visual-tactile accurate from the beginning (10 % of travel)", rule_early,
                _early_benefit(summary, obj, "hausdorff_10"))
    if "F" in objs and "visual-tactile" in objs["F"]:
        vt = objs["F"]["visual-tactile"]
        add("F (loose, arm recognisable): estimate first affected by the outer shape, then shrinks to the inner",
            "median VT Hausdorff at the end below its value at 10 % (intervals disjoint)",
            (bool(vt["final_hausdorff"]["hi"] < vt["hausdorff_10"]["lo"]),
             f"VT {_cm(vt['hausdorff_10']['median'])} cm at 10 % -> {_cm(vt['final_hausdorff']['median'])} "
             "cm at the end"))
    if "H" in objs:
        add("H (loose garment): no harm from vision", rule_harm, _no_harm(summary, "H"))
    corr = {o: objs[o]["visual-tactile"]["final_correlation"] for o in objs if "visual-tactile" in objs[o]}
    if "H" in corr and len(corr) > 1 and set(corr) <= set("EFGH"):
        others = [c["lo"] for o, c in corr.items() if o != "H"]
        add("Fig. 10: H has the lowest similarity (task correlation)",
            "H's median the lowest and the upper end of its 95 % interval below every other lower end",
            (bool(corr["H"]["hi"] < min(others)), ", ".join(f"{o} {c['median']:.2f} [{c['lo']:.2f}, {c['hi']:.2f}]"
                                                            for o, c in sorted(corr.items()))))
    for obj in sorted(objs):
        if obj != "H":                         # H has its own "no harm" claim above
            add(f"{obj}: no harm from vision", rule_harm, _no_harm(summary, obj))
    return claims


def _equal(summary: dict, obj: str) -> tuple[bool | None, str]:
    pair = summary["paired"].get(obj, {}).get("visual-tactile", {}).get("final_hausdorff")
    t = summary["objects"][obj].get("tactile", {}).get("final_hausdorff")
    if pair is None or t is None or pair["n"] == 0:
        return None, "no paired runs"
    allowed = no_harm_margin(t)
    return bool(-allowed <= pair["lo"] and pair["hi"] <= allowed), (
        f"paired VT - T {_cm(pair['median'])} [{_cm(pair['lo'])}, {_cm(pair['hi'])}] cm (allowed +-{_cm(allowed)} cm)")


def failed_runs(rows: list[dict]) -> list[dict]:
    """The failed runs grouped by their whole reason: ``[{"reason", "runs": [key, ...]}]``, the most frequent first (a
    summary never cuts a reason short: "... is not po" left a plugin's broken kernel unnamed)."""
    groups: dict[str, list[str]] = {}
    for r in rows:
        if r["failed"]:
            groups.setdefault(r.get("reason") or r["failed"], []).append(f"{r['object']}_{r['mode']}_{r['seed']}")
    return [{"reason": why, "runs": keys} for why, keys in sorted(groups.items(), key=lambda kv: -len(kv[1]))]


def _markdown(world: str, summary: dict, claims: list[dict] | None, n_runs: int) -> str:
    lines = [f"{n_runs} runs ({world} world). Medians over seeds with distribution-free 95 % intervals "
             "(order statistics; the coverage is stated where fewer seeds make it lower). H: Hausdorff distance of the "
             "whole estimated zero set to the true inner surface, at 10 / 25 / 50 % of the reference travel and at "
             "the end; H touched: the touched estimate only; rho: task correlation; S: the paper's ratio. Failed "
             "runs (stalled, stopped by the robot, no estimate) stay in every statistic; a run with no estimate "
             "counts as inf, worse than any distance. On body: the median fraction of a run's contacts where the "
             "fingertip touched the body itself (not only the cover); '-' where the world cannot tell. Travel: the "
             "median travel [m]; re-approach: the median share of it spent re-approaching after lost contact. The "
             "field's metrics at the end: Chamfer, the mean surface-to-surface distance; F 5 mm, the "
             "F-score at 5 mm; bias, the median signed distance of the true surface from the estimate (negative: the "
             "estimate lies inside); unseen, the share of the true surface more than 2 cm from every observation.", "",
             "| object | mode | n (interval coverage) | failed (why) | H 10 % [cm] | H 25 % [cm] | H 50 % [cm] | "
             "H final [cm] | H touched final [cm] | U final | rho final | S final (paper) | on body | travel [m] | "
             "re-approach | Chamfer final [cm] | F 5 mm final | bias final [cm] | unseen final |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]

    def cell(d: dict, scale: float = 100.0, fmt: str = ".1f") -> str:
        if d["n"] == 0:
            return "-"
        return f"{scale * d['median']:{fmt}} [{scale * d['lo']:{fmt}}, {scale * d['hi']:{fmt}}]"

    for obj, modes in sorted(summary["objects"].items()):
        for mode, e in sorted(modes.items()):
            cov = e["final_hausdorff"]["coverage"]
            on_body = e.get("contacts_on_body", {"n": 0})
            lines.append(f"| {obj} | {mode} | {e['n']} ({100 * cov:.0f} %) | {e['failures']} | "
                         f"{cell(e['hausdorff_10'])} | "
                         f"{cell(e['hausdorff_25'])} | "
                         f"{cell(e['hausdorff_50'])} | {cell(e['final_hausdorff'])} | "
                         f"{cell(e['final_hausdorff_touched'])} | {cell(e['final_uncertainty'], 1, '.3f')} | "
                         f"{cell(e['final_correlation'], 1, '.2f')} | {cell(e['final_similarity'], 1, '.2f')} | "
                         f"{cell(on_body, 1, '.2f')} | {cell(e.get('travel', {'n': 0}), 1, '.2f')} | "
                         f"{cell(e.get('reapproach_share', {'n': 0}), 100, '.0f')} % | "
                         f"{cell(e.get('final_chamfer', {'n': 0}))} | "
                         f"{cell(e.get('final_fscore_5mm', {'n': 0}), 1, '.2f')} | "
                         f"{cell(e.get('final_bias', {'n': 0}))} | {cell(e.get('final_unseen', {'n': 0}), 1, '.2f')} |")
    lines += ["", "Paired differences (same seed): mode - tactile, final Hausdorff [cm], with the Wilcoxon signed-rank "
              "p-value; a pair where one side has no estimate is a loss for it (inf).", "",
              "| object | mode | n | pairs with a failure | median [95 % interval] | wins / losses | p |",
              "|---|---|---|---|---|---|---|"]
    for obj, modes in sorted(summary["paired"].items()):
        for mode, d in sorted(modes.items()):
            p = d["final_hausdorff"]
            lines.append(f"| {obj} | {mode} | {p['n']} | {p['failed']} | {cell(p)} | {p['wins']} / {p['losses']} | "
                         f"{p['p_wilcoxon']:.3g} |")
    if summary.get("failed_runs"):
        lines += ["", "Failed runs, by their whole reason:", ""]
        for group in summary["failed_runs"]:
            shown = ", ".join(group["runs"][:8]) + (f" and {len(group['runs']) - 8} more" if len(group["runs"]) > 8
                                                     else "")
            lines.append(f"- {len(group['runs'])} run(s) ({shown}): {' '.join(str(group['reason']).split())}")
    if claims is None:
        lines += ["", "Smoke sweep: the paper's claims are not judged on it."]
    else:
        lines += ["", "| claim | rule | measured | holds |", "|---|---|---|---|"]
        for c in claims:
            holds = "not judged" if c["holds"] is None else ("yes" if c["holds"] else "**no**")
            lines.append(f"| {c['claim']} | {c['rule']} | {c['measured']} | {holds} |")
    return "\n".join(lines) + "\n"
