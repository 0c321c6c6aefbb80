"""The paper's robot study (Sec. VI) in simulation: objects E-H on the simulated UR5, camera and force sensor,
visual-tactile vs tactile-only, figures like Fig. 9 and 10, and the Sec. VI-B claims measured."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..exploration import Trace
from ..session import explore
from .figures import figure_3d_object, figure_similarity
from .simulate import write_records, write_summary

__all__ = ["run_study_3d", "summarize_3d", "check_claims_3d"]

MODES = ("visual-tactile", "tactile")
OBJECTS = ("E", "F", "G", "H")
#: Fractions of the travel at which the table reports the estimates.
FRACTIONS = (0.1, 0.5, 1.0)


def _measured(trace: Trace) -> np.ndarray:
    """`(n,)` whether each record's estimate was measured (with or without a surface to judge)."""
    if len(trace.estimate) == trace.n_steps and not np.isnan(trace.estimate).all():
        return ~np.isnan(trace.estimate)
    return ~np.isnan(trace.hausdorff)                  # traces read from logs older than the estimate field


def _at(trace: Trace, distance: float) -> int:
    """Index of the first *measured* record at or after ``distance`` of travel (its value is NaN when that
    estimate had no surface: a later step's value never stands in for it)."""
    ok = np.flatnonzero(_measured(trace) & (trace.travel >= distance - 1e-12))
    return int(ok[0]) if len(ok) else trace.n_steps - 1


def estimate_counts(trace: Trace) -> tuple[int, int]:
    """``(with an estimate, measured)``: how many of a run's metric samples had a surface to judge."""
    measured = _measured(trace)
    return int((measured & np.isfinite(trace.hausdorff)).sum()), int(measured.sum())


def summarize_3d(traces: dict[str, dict[str, Trace]], hausdorff_io: dict[str, float]) -> list[dict]:
    """One row per object: Hausdorff / uncertainty at 10, 50, 100 % of the travel for both modes, similarity,
    planning time per step and simulated robot time."""
    rows = []
    for name, pair in traces.items():
        row = {"object": name, "inner_outer_hausdorff_m": hausdorff_io.get(name, float("nan"))}
        for mode, tag in (("visual-tactile", "vt"), ("tactile", "t")):
            tr = pair.get(mode)
            if tr is None:
                continue
            total = float(tr.travel[-1])
            for f in FRACTIONS:
                i = _at(tr, f * total)
                row[f"H_{tag}_{int(f * 100)}"] = float(tr.hausdorff[i])
                row[f"U_{tag}_{int(f * 100)}"] = float(tr.uncertainty[i])
                if tag == "vt":
                    row[f"S_{int(f * 100)}"] = float(tr.similarity[i])
            row[f"travel_{tag}_m"] = total
            row[f"estimate_{tag}"] = tr.has_estimate
            for k in ("chamfer", "fscore_5mm", "bias", "unseen"):          # the field's metrics at the end
                row[f"{k}_{tag}_100"] = float(tr.shape[k][-1]) if k in tr.shape and len(tr.shape[k]) else float("nan")
            row[f"reapproaches_{tag}"] = int(tr.reapproaches[-1]) if len(tr.reapproaches) else 0
            row[f"reapproach_m_{tag}"] = float(tr.reapproach_travel[-1]) if len(tr.reapproach_travel) else 0.0
            row[f"valid_{tag}"], row[f"measured_{tag}"] = estimate_counts(tr)
            row[f"steps_{tag}"] = tr.n_steps - 1
            row[f"terminated_{tag}"] = tr.terminated
            row[f"median_plan_ms_{tag}"] = 1e3 * float(np.median(tr.step_time[1:])) if tr.n_steps > 1 else float("nan")
            row[f"robot_time_s_{tag}"] = (
                float(tr.robot_time[-1] - tr.robot_time[0]) if len(tr.robot_time) else float("nan")
            )
        if "visual-tactile" in pair:
            s = pair["visual-tactile"].similarity[1:]
            row["S_mean"] = float(np.nanmean(s)) if len(s) else float("nan")
        rows.append(row)
    return rows


def check_claims_3d(rows: list[dict]) -> list[dict]:
    """The Sec. VI-B statements, each with the measured numbers and whether they hold here."""
    by = {r["object"]: r for r in rows}
    claims = []

    def cm(v: float) -> str:
        return f"{100 * v:.1f} cm"

    for name in ("E", "G"):
        r = by.get(name)
        if r is None or "H_t_10" not in r:
            continue
        holds = r["H_vt_10"] <= 0.5 * r["H_t_10"] and r["H_vt_10"] <= 1.5 * r["H_vt_100"] + 0.01
        claims.append({"claim": f"{name} (tight): visual-tactile accurate from the beginning",
                       "measured": f"H at 10 % of travel: VT {cm(r['H_vt_10'])} vs tactile {cm(r['H_t_10'])}; "
                                   f"VT final {cm(r['H_vt_100'])}", "holds": bool(holds)})
    r = by.get("F")
    if r is not None and "H_t_10" in r:
        holds = r["H_vt_100"] < r["H_vt_10"] and r["H_vt_100"] <= r["H_t_100"] + 0.01
        claims.append({"claim": "F (loose, arm recognisable): estimate first affected by the outer shape, then "
                                "shrinks to the inner",
                       "measured": f"VT H {cm(r['H_vt_10'])} at 10 % -> {cm(r['H_vt_100'])} at the end "
                                   f"(tactile {cm(r['H_t_100'])})", "holds": bool(holds)})
    r = by.get("H")
    if r is not None and "H_t_100" in r:
        diff = abs(r["H_vt_100"] - r["H_t_100"])
        holds = diff <= max(0.02, 0.25 * r["H_t_100"])
        claims.append({"claim": "H (loose garment): no benefit and no harm from vision",
                       "measured": f"final H VT {cm(r['H_vt_100'])} vs tactile {cm(r['H_t_100'])}; final U "
                                   f"{r['U_vt_100']:.3f} vs {r['U_t_100']:.3f}", "holds": bool(holds)})
    sims = {n: by[n]["S_mean"] for n in by if "S_mean" in by[n]}
    if "H" in sims and len(sims) > 1:
        holds = sims["H"] == min(sims.values())
        claims.append({"claim": "Fig. 10: H has the lowest similarity",
                       "measured": ", ".join(f"{n} {v:.2f}" for n, v in sorted(sims.items())) + " (mean over steps)",
                       "holds": bool(holds)})
    return claims


#: Least travel [m] and fewest steps every run of a 3-D study needs before the Sec. VI-B claims are judged on it
#: (a fifth of the paper's 1.5 m: the claims compare 10 % of the travel with the end).
MIN_TRAVEL_FOR_CLAIMS, MIN_STEPS_FOR_CLAIMS = 0.3, 10


def explored_enough(traces: dict) -> str | None:
    """None if every run explored enough to judge the claims, else why not (names the short runs)."""
    short = [f"{name} {mode} ({float(tr.travel[-1]):.3g} m, {tr.n_steps - 1} steps)" for name, pair in traces.items()
             for mode, tr in pair.items()
             if float(tr.travel[-1]) < MIN_TRAVEL_FOR_CLAIMS or tr.n_steps - 1 < MIN_STEPS_FOR_CLAIMS]
    if short:
        return (f"runs below {MIN_TRAVEL_FOR_CLAIMS} m of travel or {MIN_STEPS_FOR_CLAIMS} steps: {', '.join(short)}")
    return None


def _markdown(rows: list[dict], claims: list[dict] | None, why_not: str | None = None) -> str:
    def h(v):
        return "-" if v is None else ("none" if np.isnan(v) else f"{100 * v:.1f}")

    def valid(r, tag):
        return f"{r[f'valid_{tag}']} of {r[f'measured_{tag}']}" if f"valid_{tag}" in r else "-"

    lines = [
        "Columns: H is the Hausdorff distance (eq. 24) from the estimated inner surface to the true one at 10, 50 "
        "and 100 % of the run's travel ('none': the estimate had no surface inside the range there); U the "
        "uncertainty (eq. 23, relative to the prior variance); similarity the paper's K_t[0,1] / K_t[0,0]; "
        "'with estimate' how many of the run's metric samples had a surface to judge; steps, with what ended the "
        "run in brackets (travel: its budget; lost-contact, stalled, refused: the world or the robot stopped "
        "it before); travel the fingertip's "
        "travel and, in brackets, how many re-approaches after lost contact it held and how far they went; plan "
        "ms the median planning step; robot time the simulated clock. At the end: Chamfer, the mean "
        "surface-to-surface distance; F 5 mm, the F-score at 5 mm; bias, the median signed distance of the true "
        "surface from the estimate (negative: the estimate lies inside); unseen, the share of the true surface "
        "more than 2 cm from every observation.",
        "",
        "| object | d_H inner-outer [cm] | H VT 10 / 50 / 100 % [cm] | H tactile 10 / 50 / 100 % [cm] | "
        "with estimate VT / T | U VT / T final | similarity 10 / 100 % | steps (ended by) VT / T | travel VT / T [m] "
        "(re-approaches) | plan ms VT / T | robot time VT / T [s] | Chamfer VT / T [cm] | F 5 mm VT / T | "
        "bias VT / T [cm] | unseen VT / T |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]

    def pair(r, k, scale, fmt):
        vals = [r.get(f"{k}_{tag}_100") for tag in ("vt", "t")]
        return " / ".join("-" if v is None or np.isnan(v) else f"{scale * v:{fmt}}" for v in vals)

    def travel(r, tag):
        if f"travel_{tag}_m" not in r:
            return "-"
        return (f"{r[f'travel_{tag}_m']:.2f} ({r.get(f'reapproaches_{tag}', 0)}: "
                f"{r.get(f'reapproach_m_{tag}', 0.0):.2f} m)")
    def steps(r, tag):
        if f"steps_{tag}" not in r:
            return "-"
        return f"{r[f'steps_{tag}']} ({r.get(f'terminated_{tag}', '?')})"

    for r in rows:
        lines.append(
            f"| {r['object']} | {h(r['inner_outer_hausdorff_m'])} | "
            f"{h(r.get('H_vt_10'))} / {h(r.get('H_vt_50'))} / {h(r.get('H_vt_100'))} | "
            f"{h(r.get('H_t_10'))} / {h(r.get('H_t_50'))} / {h(r.get('H_t_100'))} | "
            f"{valid(r, 'vt')} / {valid(r, 't')} | "
            f"{r.get('U_vt_100', float('nan')):.3f} / {r.get('U_t_100', float('nan')):.3f} | "
            f"{r.get('S_10', float('nan')):.2f} / {r.get('S_100', float('nan')):.2f} | "
            f"{steps(r, 'vt')} / {steps(r, 't')} | {travel(r, 'vt')} / {travel(r, 't')} | "
            f"{r.get('median_plan_ms_vt', float('nan')):.0f} / {r.get('median_plan_ms_t', float('nan')):.0f} | "
            f"{r.get('robot_time_s_vt', float('nan')):.0f} / {r.get('robot_time_s_t', float('nan')):.0f} | "
            f"{pair(r, 'chamfer', 100, '.1f')} | {pair(r, 'fscore_5mm', 1, '.2f')} | {pair(r, 'bias', 100, '.1f')} | "
            f"{pair(r, 'unseen', 1, '.2f')} |")
    lost = [f"{r['object']} {mode}" for r in rows for mode, tag in (("visual-tactile", "vt"), ("tactile", "t"))
            if r.get(f"estimate_{tag}") is False]
    if lost:
        lines += ["", f"**No estimate at the end:** {', '.join(lost)}: the estimated inner surface {{mu_in = 0}} "
                      "has no surface inside the range, so there is nothing to judge (H 'none', the figure's panel "
                      "empty)."]
    if claims is None:
        lines += ["", "The paper's claims are not judged: " + (why_not or "smoke run (a few centimetres of travel)")
                  + "."]
        return "\n".join(lines) + "\n"
    if not claims:         # scene files only: the Sec. VI-B claims are about objects E-H
        lines += ["", "The paper's claims (Sec. VI-B) are about its objects E-H; none of them ran here, so there is no "
                      "claim to judge (compare visual-tactile with tactile in the table above)."]
        return "\n".join(lines) + "\n"
    lines += ["", "| claim (Sec. VI-B) | measured | holds |", "|---|---|---|"]
    for c in claims:
        lines.append(f"| {c['claim']} | {c['measured']} | {'yes' if c['holds'] else '**no**'} |")
    return "\n".join(lines) + "\n"


def _write_meshes(traces: dict, scenes: dict, out: Path, resolution: float) -> None:
    """The final inner estimate of every run (and the outer one of visual-tactile runs) as PLY meshes coloured by
    their variance, in ``out/meshes/<object>_<mode>_{inner,outer}.ply`` (for MeshLab, Blender, ``gpioius view``)."""
    from ..io.export import export_model

    for name, by_mode in traces.items():
        box = scenes[name].range + np.array([[-0.05], [0.05]])
        for mode, tr in by_mode.items():
            export_model(tr.model, out / "meshes" / f"{name}_{mode}_inner.ply", box, resolution, 0)
            if mode == "visual-tactile":
                export_model(tr.model, out / "meshes" / f"{name}_{mode}_outer.ply", box, resolution, 1)


def run_study_3d(objects=("E", "F", "G", "H"), out: str | Path = "outputs/study3d", max_travel: float = 1.5,
                 metrics_every: int = 5, modes=MODES, progress: bool = True, smoke: bool = False,
                 world: str = "forcefield", scenes=(), estimator=None, outer_tol: float | None = None,
                 **explore_kwargs) -> dict:
    """Run the simulated robot study on objects E-H and write figures, records, logs and the summary.

    Writes into ``out``: ``fig9_<object>.png``, ``fig10_similarity.png``, ``records.csv`` / ``records.json``
    (every per-step record), ``logs/<object>_<mode>.gpioius`` (exploration logs with the robot trace),
    ``summary.json`` and ``summary.md`` (table and the Sec. VI-B claims as measured).

    Why this many parameters: it is ``gpioius simulate3d``'s body, one parameter per flag (the estimator's settings are
    one, ``estimator``); the rest pass to :func:`torch_gpioius.explore`.

    Args:
        objects: names among E-H.
        out: output folder (created).
        max_travel: fingertip travel per run [m] (paper: 1.5).
        metrics_every: compute the surface metrics every k steps (and at the last one).
        modes: which modes to run.
        progress: progress bars.
        smoke: a CI run on coarser objects: figures and records as usual, but the claims are not judged.
        world: a registered world with the objects E-H: "forcefield" (``tg.sim.paper_objects_3d``) or "mujoco"
            (``tg.sim.mujoco_objects_3d``: cloth and foam covers on MuJoCo's contact physics; the ``mujoco`` extra).
        scenes: scene files (:mod:`torch_gpioius.sim.scenefile`) explored as further objects, named by their
            ``name`` (the claims are judged on E-H only).
        estimator: changes to each scene's own estimator settings (an
            :class:`~torch_gpioius.models.overrides.EstimatorOverrides` or its plain dict: the camera's voxel, the
            kernel, sigma^2, any label; ``gpioius simulate3d``'s estimator flags); None: each scene's own (the
            paper's for E-H). ``voxel=`` of earlier releases is read for one release, as
            ``estimator=EstimatorOverrides(voxel=...)``, with a DeprecationWarning.
        outer_tol: the visual-tactile runs with a truncated outer basis (``explore(outer_tol=...)``); the
            tactile-only runs have no camera points. None: exact.
        **explore_kwargs: forwarded to ``explore`` (step, settings, device, ...).
    """
    from ..exploration.registry import world_entry
    from ..io.outputs import StagedFiles
    from ..models.overrides import EstimatorOverrides, resolved_changes, warn_loose

    entry = world_entry(world)
    if warn_loose("run_study_3d", 2, voxel=explore_kwargs.get("voxel")):
        estimator = resolved_changes(estimator).merged(EstimatorOverrides(voxel=explore_kwargs.pop("voxel")))
    explore_kwargs.pop("voxel", None)
    estimator = resolved_changes(estimator) or None
    if estimator is not None and ("policy" in explore_kwargs or "settings" in explore_kwargs):
        raise ValueError("estimator: give either estimator or policy / settings (whose values it would change), not "
                         "both")
    unknown = [o for o in objects if o not in OBJECTS or o not in entry.object_names]
    if unknown:   # before building the meshes (seconds)
        raise ValueError(f"objects: unknown {unknown} in the {entry.name} world; choose among "
                         f"{[o for o in OBJECTS if o in entry.object_names]}")
    from ..sim.scenefile import load_scene, read_scene

    files = [Path(p) for p in ([scenes] if isinstance(scenes, (str, Path)) else scenes)]
    names = [read_scene(p).name for p in files]                     # fails on a bad file before anything runs
    if len(set(names) | set(objects)) < len(names) + len(objects):
        raise ValueError(f"scenes: the names {names} repeat each other or the objects {list(objects)}")
    scenes = {o: entry.build(o, smoke) for o in objects}
    scenes.update({n: load_scene(p, world=entry.name, smoke=smoke) for n, p in zip(names, files)})
    objects = list(scenes)
    final = Path(out)
    final.mkdir(parents=True, exist_ok=True)
    # the run's files are written into a staging folder and moved in at the end: a run killed half-way leaves the
    # earlier run's logs, records and summary whole, never the new run's logs beside the old run's summary
    with StagedFiles(final) as staged:
        return _run_study_3d(scenes, objects, modes, staged.path, max_travel, metrics_every, progress, smoke,
                             estimator, outer_tol, explore_kwargs)


def _run_study_3d(scenes: dict, objects: list, modes, out: Path, max_travel: float, metrics_every: int,
                  progress: bool, smoke: bool, estimator, outer_tol: float | None, explore_kwargs: dict) -> dict:
    """:func:`run_study_3d`'s runs, figures and tables, written into ``out`` (its staging folder)."""
    from ..core.progress import progress as reporter

    (out / "logs").mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    traces: dict[str, dict[str, Trace]] = {}
    jobs = [(o, m) for o in objects for m in modes]
    bar = reporter(len(jobs), "3-D study", progress)
    # the correlation's 95 % profile-likelihood interval every 10 steps and at the end (the figures' bands)
    explore_kwargs.setdefault("interval_every", 1000 if smoke else 10)
    for name, mode in jobs:
        bar.set_postfix_str(f"object {name}, {mode}")
        kw = dict(explore_kwargs)
        if estimator is not None:         # each scene's own settings with these changes
            kw["settings"] = estimator
        if outer_tol is not None and mode == "visual-tactile":
            kw["outer_tol"] = outer_tol
        traces.setdefault(name, {})[mode] = explore(
            scenes[name], mode=mode, max_travel=max_travel, metrics_every=metrics_every, progress=progress,
            log=out / "logs" / f"{name}_{mode}.gpioius", overwrite=True, **kw)
        bar.update(1)
    bar.close()
    hio = {name: scenes[name].inner_outer_hausdorff() for name in objects}
    for name in objects:
        figure_3d_object(name, scenes[name], traces[name], out / f"fig9_{name}.png")
    figure_similarity(traces, out / "fig10_similarity.png", "Similarity transitions (cf. Fig. 10)")
    _write_meshes(traces, scenes, out, 0.02 if smoke else 0.01)
    write_records(traces, out)
    rows = summarize_3d(traces, hio)
    why_not = "smoke run (a few centimetres of travel)" if smoke else explored_enough(traces)
    claims = None if why_not else check_claims_3d(rows)
    write_summary(out, rows, claims, why_not, _markdown)
    return {"traces": traces, "rows": rows, "claims": claims, "seconds": time.perf_counter() - t0}
