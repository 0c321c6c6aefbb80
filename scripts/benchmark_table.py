"""The object-set benchmark's tables and figures (docs/results-benchmark.md): accuracy as a distribution over objects.

Each arm is a label and one or more study folders (``gpioius study --objects SET``), e.g. the tight covers of both
families under the default settings. For every arm and mode it prints the distribution over the objects' runs of the
final Chamfer distance, the F-scores at 5 mm and 1 cm, the signed bias, the Hausdorff distance at 25 % of the travel
and at the end, the correlation, the travel and the wall time (median, interquartile range, 90th percentile), the
failures by cause; the simple baselines every visual-tactile run scored from its own observations (vision alone,
vision shrunk by the touches' gap; rows ``baseline:<name>``) beside the method in every table; then visual-tactile
against touch alone paired per object (and seed), the goals of the benchmark judged, GPIOIS against each baseline and
against the best of them paired per object, the five worst objects by Chamfer distance, and a leaderboard
(``--summary``); with ``--figures`` the distributions' CDFs.

    python scripts/benchmark_table.py "tight=outputs/benchmark/primitives-tight,outputs/benchmark/random-tight" \\
        --summary outputs/benchmark/summary.md --figures outputs/benchmark
"""

from __future__ import annotations

import argparse
import csv
import math
from collections import Counter
from pathlib import Path

import numpy as np

#: (column of runs.csv, heading, scale to the printed unit, format)
METRICS = [("final_chamfer", "Chamfer [cm]", 100, ".2f"), ("final_fscore_5mm", "F 5 mm", 1, ".2f"),
           ("final_fscore_10mm", "F 1 cm", 1, ".2f"), ("final_bias", "bias [mm]", 1000, ".1f"),
           ("hausdorff_25", "H 25 % [cm]", 100, ".1f"), ("final_hausdorff", "H final [cm]", 100, ".1f"),
           ("final_correlation", "rho final", 1, ".2f"), ("travel", "travel [m]", 1, ".2f"),
           ("wall_time", "wall [s]", 1, ".0f")]


class ArmError(ValueError):
    """An arm that cannot be read: the message names the argument, the folder or the file."""


#: The columns every arm's runs.csv must hold.
NEEDED = ("object", "mode", "seed")


def read_arm(spec: str) -> tuple[str, list[dict]]:
    """``label=folder[,folder...]`` -> (label, the rows of every folder's runs.csv).

    Raises:
        ArmError: an argument without a label or a folder, a folder that does not exist or holds no runs.csv (a study
            still running, or another folder), or a runs.csv without the columns a study writes.
    """
    label, eq, folders = spec.partition("=")
    if not eq or not label.strip() or not folders.strip():
        raise ArmError(f"{spec!r}: an arm is LABEL=FOLDER[,FOLDER...] (e.g. \"tight=outputs/benchmark/p-tight\")")
    rows = []
    for folder in (f.strip() for f in folders.split(",") if f.strip()):
        path = Path(folder) / "runs.csv"
        if not Path(folder).is_dir():
            raise ArmError(f"{label}: {folder} is not a folder")
        if not path.is_file():
            raise ArmError(f"{label}: {folder} holds no runs.csv (is it a study folder? a study writes runs.csv "
                           "when its runs have ended)")
        try:
            with open(path, newline="") as f:
                found = list(csv.DictReader(f))
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise ArmError(f"{label}: {path} cannot be read ({exc})") from None
        missing = [k for k in NEEDED if found and k not in found[0]]
        if missing:
            raise ArmError(f"{label}: {path} has no column {missing}; is it a study's runs.csv?")
        rows += found
    if not rows:
        raise ArmError(f"{label}: no runs in {folders}")
    return label.strip(), rows


#: What a run without an estimate scores (the studies' rule: it stays in every statistic, worse than any other).
NO_ESTIMATE = {"final_fscore_5mm": 0.0, "final_fscore_10mm": 0.0}


#: The baselines' columns of runs.csv (``baseline_<name>_<metric>``) and the run columns they stand for.
BASELINE_KEYS = {"chamfer": "final_chamfer", "fscore_5mm": "final_fscore_5mm", "fscore_10mm": "final_fscore_10mm",
                 "bias": "final_bias", "hausdorff": "final_hausdorff"}


def with_baselines(rows: list[dict]) -> list[dict]:
    """``rows`` and, for each visual-tactile run that scored them, one row per simple baseline (mode
    ``baseline:<name>``: vision alone, vision shrunk by the touches' gap; the studies' ``baseline_*`` columns) with
    the run's object and seed, so that every table and figure sets them beside the method. Touch alone is the study's
    own ``tactile`` mode."""
    out = list(rows)
    measured = sorted({k[len("baseline_"):-len("_chamfer")] for r in rows for k in r
                       if k.startswith("baseline_") and k.endswith("_chamfer") and r[k] not in ("", "nan")})
    for r in rows:
        if r["mode"] != "visual-tactile":
            continue
        names = [n for n in measured if r.get(f"baseline_{n}_chamfer") not in (None, "", "nan")]
        if not names and cause(r):
            # a run refused before it observed anything (its scene, its approach): no baseline has an estimate
            # either, and each counts as failed, as the method does
            names = measured
        for name in names:
            b = {"object": r["object"], "seed": r["seed"], "mode": f"baseline:{name}", "failed": "",
                 "terminated": "baseline", "travel": r.get("travel", "nan"), "wall_time": "nan"}
            for short, key in BASELINE_KEYS.items():
                b[key] = r.get(f"baseline_{name}_{short}", "nan")
            b["has_estimate"] = str(math.isfinite(float(b["final_chamfer"])))
            if b["has_estimate"] == "False":
                b["failed"] = "no estimate"
            out.append(b)
    return out


def best_baseline(rows: list[dict], key: str = "final_chamfer") -> dict:
    """Visual-tactile against the best of the baselines on the same object and seed (the lowest ``key`` of touch
    alone and every ``baseline:<name>`` row there): the share of pairs where the method is strictly ahead, the median
    difference and how often each baseline was the best one."""
    by: dict = {}
    for r in rows:
        by.setdefault((r["object"], r["seed"]), {})[r["mode"]] = number(r, key)
    diffs, best = [], Counter()
    for modes in by.values():
        if "visual-tactile" not in modes:
            continue
        others = {m: v for m, v in modes.items() if m == "tactile" or m.startswith("baseline:")}
        others = {m: v for m, v in others.items() if not math.isnan(v)}
        if not others:
            continue
        winner = min(others, key=others.get)
        best[winner] += 1
        diffs.append(modes["visual-tactile"] - others[winner])
    d = np.array([x for x in diffs if not math.isnan(x)])
    return {"n": len(d), "ahead": float((d < 0).mean()) if len(d) else math.nan,
            "median": float(np.median(d)) if len(d) else math.nan, "best": dict(best.most_common())}


def number(row: dict, key: str) -> float:
    """``row[key]`` as a number; a run without a final estimate (a scene that could not be built, an estimate that
    vanished) counts as the worst: an infinite distance, an F-score of 0, no bias or correlation."""
    if row.get("has_estimate") not in (None, "True") and (key.startswith(("final_", "hausdorff_"))):
        return NO_ESTIMATE.get(key, math.nan if key in ("final_bias", "final_correlation") else math.inf)
    try:
        return float(row.get(key, "nan"))
    except ValueError:
        return math.nan


def cause(row: dict) -> str:
    """Why a run failed, in a few words ("" if it did not; the study's ``failed`` column)."""
    why = row.get("failed", "")
    if why in ("", "0", "False"):
        return ""
    return "scene cannot be built" if why.startswith("scene:") else why


def pct(values, p: float) -> float:
    """The ``p``-th percentile as an order statistic (the smallest value with at least p % at or below it): the
    failed runs' infinite distances count as the worst values, never interpolated into a finite one."""
    v = np.sort(np.asarray(values, dtype=float)[~np.isnan(np.asarray(values, dtype=float))])
    return float(v[max(0, int(math.ceil(p / 100 * len(v))) - 1)]) if len(v) else math.nan


def spread(values: np.ndarray, fmt: str) -> str:
    """median [q25, q75] p90 (:func:`pct`; a failed run's inf counts as the worst)."""
    if np.isnan(values).all():
        return "-"
    q = [pct(values, p) for p in (50, 25, 75, 90)]
    return f"{q[0]:{fmt}} [{q[1]:{fmt}}, {q[2]:{fmt}}] {q[3]:{fmt}}"


def distribution_table(arms: dict[str, list[dict]]) -> str:
    head = ["arm", "mode", "runs", "failed (why)"] + [m[1] for m in METRICS]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for label, rows in arms.items():
        for mode in sorted({r["mode"] for r in rows}):
            sel = [r for r in rows if r["mode"] == mode]
            failed = Counter(cause(r) for r in sel if cause(r))
            why = ", ".join(f"{n} {k}" for k, n in failed.most_common()) or "0"
            cells = [spread(np.array([number(r, k) * s for r in sel]), f) for k, _, s, f in METRICS]
            out.append(f"| {label} | {mode} | {len(sel)} | {why} | " + " | ".join(cells) + " |")
    return "\n".join(out)


def paired(rows: list[dict], key: str, against: str = "tactile") -> dict:
    """Visual-tactile against another mode (touch alone, or a ``baseline:<name>``) on the same object and seed: the
    share of pairs where the method is ahead (strictly lower ``key``), the median difference and the pairs."""
    by = {(r["object"], r["seed"], r["mode"]): number(r, key) for r in rows}
    diffs = [by[(o, s, "visual-tactile")] - by[(o, s, against)] for (o, s, m) in by
             if m == "visual-tactile" and (o, s, against) in by]
    d = np.array([x for x in diffs if not math.isnan(x)])
    return {"n": len(d), "ahead": float((d < 0).mean()) if len(d) else math.nan,
            "median": float(np.median(d)) if len(d) else math.nan}


def goals(label: str, rows: list[dict], wide: bool) -> list[str]:
    vt = [r for r in rows if r["mode"] == "visual-tactile"]
    if not vt:
        return [f"{label}: no visual-tactile runs, so no goal of the benchmark is judged (modes: "
                f"{', '.join(sorted({r['mode'] for r in rows}))})"]
    ch = np.array([number(r, "final_chamfer") for r in vt]) * 100
    f1 = np.array([number(r, "final_fscore_10mm") for r in vt])
    p25 = paired(rows, "hausdorff_25")
    pfinal = paired(rows, "final_chamfer")
    out = []
    if wide:
        out.append(f"{label}: no harm at the median (VT - T final Chamfer): {100 * pfinal['median']:+.2f} cm over "
                   f"{pfinal['n']} pairs -> {'holds' if pfinal['median'] <= 0.001 else 'fails'}")
        return out
    med, p90 = pct(ch, 50), pct(ch, 90)
    out.append(f"{label}: median Chamfer {med:.2f} cm (goal <= 0.6), 90th percentile {p90:.2f} cm (goal <= 1.2) -> "
               f"{'holds' if med <= 0.6 and p90 <= 1.2 else 'fails'}")
    out.append(f"{label}: median F-score at 1 cm {pct(f1, 50):.2f} (goal >= 0.9) -> "
               f"{'holds' if pct(f1, 50) >= 0.9 else 'fails'}")
    out.append(f"{label}: visual-tactile ahead of touch alone at 25 % of the travel on {100 * p25['ahead']:.0f} % of "
               f"{p25['n']} pairs (goal >= 80 %; median VT - T {100 * p25['median']:+.1f} cm) -> "
               f"{'holds' if p25['ahead'] >= 0.8 else 'fails'}")
    return out


def baseline_lines(label: str, rows: list[dict]) -> list[str]:
    """The method against each baseline and against the best of them, paired per object and seed (final Chamfer)."""
    out = []
    best = best_baseline(rows)
    if best["n"]:
        names = ", ".join(f"{m.removeprefix('baseline:')} {n}" for m, n in best["best"].items())
        out.append(f"{label}: GPIOIS ahead of the best baseline on {100 * best['ahead']:.0f} % of {best['n']} objects, "
                   f"paired (final Chamfer; median VT - best {100 * best['median']:+.2f} cm; the best was: {names})")
    for mode in sorted({r["mode"] for r in rows if r["mode"] == "tactile" or r["mode"].startswith("baseline:")}):
        p = paired(rows, "final_chamfer", mode)
        if p["n"]:
            out.append(f"{label}: GPIOIS against {mode.removeprefix('baseline:')}: ahead on {100 * p['ahead']:.0f} % "
                       f"of {p['n']} pairs, median VT - it {100 * p['median']:+.2f} cm")
    return out


def worst(rows: list[dict], k: int = 5) -> list[str]:
    def badness(r: dict) -> float:
        v = number(r, "final_chamfer")
        return -(math.inf if math.isnan(v) else v)

    vt = sorted((r for r in rows if r["mode"] == "visual-tactile"), key=badness)
    return [f"{r['object']} (seed {r['seed']}): Chamfer {100 * number(r, 'final_chamfer'):.2f} cm, F 1 cm "
            f"{number(r, 'final_fscore_10mm'):.2f}, bias {1000 * number(r, 'final_bias'):.1f} mm, "
            f"H final {100 * number(r, 'final_hausdorff'):.1f} cm, {ended(r)}" for r in vt[:k]]


#: How a run's ``terminated`` reads in a sentence.
ENDINGS = {"travel": "ended at its travel budget", "max_steps": "ended at its step cap",
           "stalled": "stopped: no progress", "lost-contact": "lost contact", "no-contact": "found no contact"}


def ended(row: dict) -> str:
    """How a run ended, in words: its failure's whole reason where it failed (the ``reason`` column of studies that
    record it, never cut), else its stop rule."""
    t = row.get("reason") or row.get("terminated", "")
    if cause(row):
        return f"failed: {t}" if t else f"failed: {cause(row)}"
    return ENDINGS.get(t, f"ended: {t}" if t else "ended")


def leaderboard(arms: dict[str, list[dict]]) -> str:
    out = ["| arm | mode | objects | Chamfer median [cm] | Chamfer p90 [cm] | F 1 cm median | bias median [mm] |",
           "|---|---|---|---|---|---|---|"]
    board = []
    for label, rows in arms.items():
        for mode in sorted({r["mode"] for r in rows}):
            sel = [r for r in rows if r["mode"] == mode]
            ch = np.array([number(r, "final_chamfer") for r in sel]) * 100
            board.append((pct(ch, 50), label, mode, len(sel), pct(ch, 90),
                          pct([number(r, "final_fscore_10mm") for r in sel], 50),
                          1000 * pct([number(r, "final_bias") for r in sel], 50)))
    for med, label, mode, n, p90, f1, bias in sorted(board):
        out.append(f"| {label} | {mode} | {n} | {med:.2f} | {p90:.2f} | {f1:.2f} | {bias:.1f} |")
    return "\n".join(out)


#: How each mode is drawn in the CDF figures: (colour, line style, label).
STYLES = {"visual-tactile": ("tab:blue", "-", "GPIOIS (visual-tactile)"),
          "tactile": ("tab:orange", "--", "touch alone"),
          "baseline:vision": ("0.5", ":", "vision alone"),
          "baseline:vision-shrunk-5": ("tab:green", "-.", "vision shrunk by the first 5 touches' gap"),
          "baseline:vision-shrunk-all": ("tab:red", (0, (5, 2, 1, 2, 1, 2)), "vision shrunk by all touches' gap")}


def figures(arms: dict[str, list[dict]], folder: Path) -> list[Path]:
    """One figure per metric: a panel per arm, each the CDF over its objects of the method, touch alone and every
    baseline (one colour and line per mode throughout), the x axis clipped to the 95th percentile of every curve."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    cols = min(3, len(arms))
    rows_n = int(math.ceil(len(arms) / cols))
    for key, title, scale, _ in METRICS[:5]:
        fig, axes = plt.subplots(rows_n, cols, figsize=(4.2 * cols, 3.2 * rows_n + 0.8), squeeze=False,
                                 sharey=True)
        drawn: dict = {}
        for ax, (label, rows) in zip(axes.ravel(), arms.items()):
            tops = []
            for mode in [m for m in STYLES if any(r["mode"] == m for r in rows)]:
                v = np.sort(np.array([number(r, key) * scale for r in rows if r["mode"] == mode]))
                v = v[~np.isnan(v)]
                if not len(v):
                    continue
                colour, style, name = STYLES[mode]
                finite = v[np.isfinite(v)]
                if len(finite):
                    tops.append(pct(finite, 95))
                drawn[name] = ax.step(v, np.arange(1, len(v) + 1) / len(v), color=colour, ls=style, where="post",
                                      lw=1.4)[0]
            if tops:
                ax.set_xlim(left=min(0.0, ax.get_xlim()[0]), right=max(tops) * 1.05)
            ax.set_title(label, fontsize=10)
            ax.set_xlabel(title)
            ax.grid(alpha=0.3)
        for ax in axes[:, 0]:
            ax.set_ylabel("share of objects")
        for ax in axes.ravel()[len(arms):]:
            ax.axis("off")
        fig.legend(list(drawn.values()), list(drawn), loc="lower center", ncol=min(3, len(drawn)), fontsize=8,
                   frameon=False)
        fig.tight_layout(rect=(0, 0.08 if rows_n > 1 else 0.14, 1, 1))
        path = folder / f"cdf_{key}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("arms", nargs="+", help='label=folder[,folder...] (e.g. "tight=outputs/benchmark/p-tight")')
    parser.add_argument("--wide", nargs="*", default=[], help="labels of arms under wide covers (no-harm goal)")
    parser.add_argument("--summary", type=Path, default=None, help="write the leaderboard and goals there")
    parser.add_argument("--figures", type=Path, default=None, help="write CDF figures into this folder")
    args = parser.parse_args()
    try:
        arms = {label: with_baselines(rows) for label, rows in (read_arm(a) for a in args.arms)}
    except ArmError as exc:
        parser.error(str(exc))
    unknown = [w for w in args.wide if w not in arms]
    if unknown:
        parser.error(f"--wide: {unknown} name no arm; the arms are {sorted(arms)}")
    table = distribution_table(arms)
    print(table, "\n")
    lines = [g for label, rows in arms.items() for g in goals(label, rows, label in args.wide)]
    lines += [g for label, rows in arms.items() for g in baseline_lines(label, rows)]
    print("\n".join(lines), "\n")
    for label, rows in arms.items():
        print(f"five worst of {label}:\n  " + "\n  ".join(worst(rows)))
    board = leaderboard(arms)
    print("\n" + board)
    if args.summary is not None:
        args.summary.write_text("# Benchmark leaderboard\n\n" + board + "\n\n## Goals\n\n" +
                                "\n".join(f"- {g}" for g in lines) + "\n\n## Distributions\n\n" + table + "\n")
    if args.figures is not None:
        args.figures.mkdir(parents=True, exist_ok=True)
        print("wrote", ", ".join(str(p) for p in figures(arms, args.figures)))


if __name__ == "__main__":
    main()
