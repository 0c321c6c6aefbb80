"""Command-line interface: ``gpioius simulate | simulate3d | study | fit | replay | import-bag | view | export``.

Every command runs its GP arithmetic on ``--threads`` torch threads (default 1: on 2-core machines under load two
threads per process made runs 2-3x slower with identical results; docs/performance.md). Bad input prints one
line ``gpioius: error: ...`` and exits with status 2.

No command replaces what exists unless given ``--force``: an output file must be new, an output folder new, empty
or written before by the same command (:mod:`torch_gpioius.io.outputs`).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import warnings
from pathlib import Path

__all__ = ["main"]


def _simulate(args: argparse.Namespace) -> int:
    from .io.outputs import FolderLock, claimed_folder
    from .studies.simulate import run_study

    objects = list(_objects_of("planar")) if args.object == "all" else [args.object]
    max_steps = 12 if args.smoke else args.max_steps
    # the folder's summary, records and figures describe one set of objects: another set is another run
    with claimed_folder(args.out, "simulate", args.force, objects=",".join(objects), added=("objects",)), \
            FolderLock(args.out, "gpioius simulate"):
        result = run_study(objects, out=args.out, max_steps=max_steps, progress=not args.quiet, smoke=args.smoke)
    print((Path(args.out) / "summary.md").read_text())
    print(f"wrote figures, records.csv/json and summary.md to {args.out} in {result['seconds']:.0f} s")
    return 0


def _simulate3d(args: argparse.Namespace) -> int:
    from .io.outputs import FolderLock, claimed_folder
    from .studies.simulate3d import run_study_3d

    if args.outer_tol is not None and args.touch == "patch":
        raise SystemExit("gpioius simulate3d: --outer-tol: patch runs use the batched engine, which has no truncated "
                         "outer basis")
    scenes = [] if args.scene is None else args.scene.split(",")
    if args.object is None:
        objects = [] if scenes else list(_robot_study_objects())
    else:
        objects = list(_robot_study_objects()) if args.object == "all" else [args.object]
    identity = {} if args.outer_tol is None else {"outer_tol": args.outer_tol}   # older folders: exact
    estimator = _estimator_overrides(args)
    others = dataclasses.replace(estimator, voxel=None).to_dict()      # the voxel: the folder's key since before
    travel = 0.06 if args.smoke else args.max_travel
    # a scene refused when it is built leaves no folder behind
    with claimed_folder(args.out, "simulate3d", args.force, world=args.world, voxel=estimator.voxel,
                        touch=None if args.touch == "point" else args.touch,   # older folders: point
                        objects=",".join([*objects, *(str(Path(s).resolve()) for s in scenes)]),
                        estimator=others or None, added=("objects", "estimator"),
                        **identity), FolderLock(args.out, "gpioius simulate3d"):
        result = run_study_3d(objects, out=args.out, max_travel=travel, metrics_every=args.metrics_every,
                              progress=not args.quiet, smoke=args.smoke, world=args.world, scenes=scenes,
                              estimator=estimator or None, touch=args.touch, outer_tol=args.outer_tol,
                              device=args.device)
    print((Path(args.out) / "summary.md").read_text())
    print(f"wrote figures, records.csv/json, logs/ and summary.md to {args.out} in {result['seconds']:.0f} s")
    return 0


def _study(args: argparse.Namespace) -> int:
    from .studies.study import run_sweep

    # an object set (a name with a colon) is one value, commas included (pybullet:duck,teddy; primitives:0-9,20)
    objects = None if args.objects is None else ([args.objects] if ":" in args.objects else args.objects.split(","))
    scenes = [] if args.scenes is None else args.scenes.split(",")
    result = run_sweep(world=args.world, objects=objects, scenes=scenes, modes=args.modes.split(","),
                       seeds=args.seeds, out=args.out, workers=args.workers, address=args.address,
                       max_travel=args.max_travel, max_steps=args.max_steps, smoke=args.smoke,
                       progress=not args.quiet, threads=args.threads, force=args.force, touch=args.touch,
                       outer_tol=args.outer_tol, device=args.device, settings=args.settings, views=args.views,
                       cover=args.cover, metrics_every=args.metrics_every, camera_error=args.camera_error,
                       camera_bound=args.camera_bound, estimator=_estimator_overrides(args))
    print((Path(args.out) / "summary.md").read_text())
    print(f"{result['runs']} runs ({result['skipped']} already done) in {result['seconds']:.0f} s on "
          f"{result['backend']}; wrote runs.csv, summary.json, summary.md and figures to {args.out}")
    if result["rows"] and all(r["failed"] for r in result["rows"]):
        # a study none of whose runs gave a result answers nothing: a script that runs it must be able to tell
        print(f"gpioius study: every run failed ({len(result['rows'])}); the reasons are listed above",
              file=sys.stderr)
        return 1
    return 0


def _fit(args: argparse.Namespace) -> int:
    own = Path(args.dataset).suffix.lower() == ".csv"
    if not own and (args.cloud or args.camera_origin or args.units != "m" or args.contact_spacing is not None
                    or args.camera_bound is not None or args.table is not None):
        raise ValueError("fit: --cloud, --units, --camera-origin, --contact-spacing, --camera-bound and --table go "
                         "with a contacts CSV (a .gpioius file holds its own cloud, in metres)")
    if args.table is not None and args.camera_bound is None:
        raise ValueError("fit: --table holds the captures to the table while --camera-bound corrects them: give both")
    origins = []
    for text in args.camera_origin or []:
        try:
            origins.append([float(v) for v in text.replace(",", " ").split()] or None)
        except ValueError:
            raise ValueError(f"--camera-origin: expected three numbers \"x y z\", got {text!r}") from None
    clouds = args.cloud or []
    if origins and len(origins) != len(clouds):
        raise ValueError(f"--camera-origin: {len(origins)} given for {len(clouds)} --cloud file(s); give one per "
                         "cloud, in the same order")
    overrides = _estimator_overrides(args)
    if not own and (overrides.voxel is not None or overrides.labels):
        raise ValueError("fit: --voxel and --estimator labels.* label a contacts CSV and its clouds; a .gpioius file "
                         "holds its observations labelled already")
    from contextlib import nullcontext

    from .fitting import fit_outputs
    from .io.outputs import check_not_inputs, claimed_folder

    # --force replaces results, never the data: checked before the import
    check_not_inputs(fit_outputs(args.out, args.mesh, args.outer_mesh), [args.dataset, *clouds])
    from .core.progress import Heartbeat

    # arguments checked first; a fit refused or failed leaves no folder behind; a long one says what it does
    with claimed_folder(args.out, "fit", args.force) if args.out else nullcontext(), \
            Heartbeat("gpioius fit") if not args.quiet else nullcontext():
        info = _fit_files(args, own, clouds, origins, overrides)
    _fit_report(args, info)
    return 0


def _fit_files(args: argparse.Namespace, own: bool, clouds: list, origins: list, overrides) -> dict:
    """`gpioius fit`'s import (a contacts CSV and clouds) and fit, with the estimator's flags (``overrides``, an
    :class:`~torch_gpioius.models.overrides.EstimatorOverrides`) on the settings: a user's files are labelled, sized
    and fitted with them; a dataset file is fitted with its kernel, sigma^2 and learning changed."""
    from .fitting import fit_dataset
    from .models.estimator import EstimatorSettings

    source = args.dataset
    settings = args.settings if args.settings is not None else ("default" if own else None)
    if own:
        from .io.importers import dataset_from_files

        cloud = None if not clouds else (clouds[0] if len(clouds) == 1 else clouds)
        origin = None if not origins else (origins[0] if len(origins) == 1 else origins)
        # the files labelled, the voxel and length sized, and the model fitted with the flags' settings
        ds = dataset_from_files(args.dataset, cloud, units=args.units, camera_origin=origin,
                                settings=overrides.apply(EstimatorSettings.of(settings)),
                                contact_spacing=args.contact_spacing, camera_bound=args.camera_bound, table=args.table)
        ds.meta["files"] = " + ".join(str(p) for p in (args.dataset, *clouds) if p)
        return fit_dataset(ds, args.out, mesh=args.mesh, outer_mesh=args.outer_mesh, resolution=args.resolution,
                           force=args.force)                # the dataset holds the settings it was labelled with
    # a dataset file: the flags change the preset asked for, else the file's own settings
    settings = overrides.apply(EstimatorSettings.of(settings)) if settings is not None else (overrides or None)
    return fit_dataset(source, args.out, settings=settings, mesh=args.mesh, outer_mesh=args.outer_mesh,
                       resolution=args.resolution, force=args.force)


def _fit_report(args: argparse.Namespace, info: dict) -> None:
    """What `gpioius fit` prints of a fit."""
    if info["settings"] is not None:
        from .models.estimator import EstimatorSettings

        print(EstimatorSettings.from_dict(info["settings"]).summary())
    print(f"{args.dataset}: {info['n']} observations ({info['n_inner']} inner, {info['n_outer']} outer), "
          f"lengthscale = {info['lengthscale']:g} m, sigma^2 = {info['noise']:g}")
    if "learned" in info:
        r = info["learned"]
        print(f"learned ({args.learn}, {r['points']} points, {r['evaluations']} evaluations): length = "
              f"{r['length']:.4g} m, sigma^2 = {r['noise']:.4g}, "
              + ("kept (the full data's log marginal likelihood rose)" if r["kept"] else
                 "not kept (the full data's log marginal likelihood fell; the given values stay)"))
    if "task_covariance" in info:
        kt = info["task_covariance"]
        print(f"K_t = [[{kt[0][0]:.5g}, {kt[0][1]:.5g}], [{kt[1][0]:.5g}, {kt[1][1]:.5g}]]")
        lo, hi = info["correlation_interval"]
        print(f"correlation = {info['correlation']:.4f}, 95 % profile-likelihood interval [{lo:.2f}, {hi:.2f}]   "
              f"(the paper's similarity K_t[0,1]/K_t[0,0] = {info['similarity']:.4f})")
        support = info["similarity_support"]
        print("  " + (support["reason"] if not support["enough"] else _interval_reading(lo, hi)))
    else:
        print("no outer observations: fitted a tactile-only GPIS")
    print(f"log marginal likelihood = {info['mll']:.4f}")
    if info.get("camera_corrections"):
        from .sensors.extrinsics import misfit_text

        c = info["camera_corrections"]
        print(f"captures corrected from the contacts (within {c['bound']['translation_mm']:g} mm and "
              f"{c['bound']['rotation_deg']:g} deg): " + "; ".join(
                  f"{k}: {e['size_mm']:.1f} mm, {e['angle_deg']:.2f} deg ({e['contacts']} contacts under it)"
                  for k, e in enumerate(c["captures"]))
              + f"; {misfit_text(c)}")
    if info.get("converged") is False:
        print(f"  ({info['fit_note']})")
    if not info["estimate"]:
        print(f"no estimate: no surface to show or export; {info['no_estimate']}")
    for key, what in (("mesh", "the inner estimate"), ("outer_mesh", "the outer estimate")):
        if info.get(key):
            print(f"wrote {what} to {info[key]}")
    if args.out:
        print(f"wrote {info['checkpoint']}, {info['figure']} and {Path(args.out) / 'fit.json'}")
    if info.get("baselines"):
        gaps = ", ".join(f"{name}" + (f" (gap {b['gap'] * 1000:.1f} mm)" if b["gap"] is not None else "")
                         for name, b in info["baselines"].items() if b["mesh"])
        print(f"wrote the simple baselines from the same observations to {Path(args.out) / 'baselines'}: {gaps}")


def _interval_reading(lo: float, hi: float) -> str:
    """One line on what a correlation interval says (docs/theory.md, the profile interval)."""
    if lo <= 0.0 <= hi and hi < 1.0:
        return ("the data cannot tell whether the outer shape predicts the inner one (the interval holds 0), but they "
                "rule out that it predicts it perfectly (it excludes 1)")
    if lo <= 0.0 <= hi:
        return "the data cannot tell yet how much the outer shape predicts the inner one (the interval holds 0 and 1)"
    if hi >= 1.0:
        return "the outer shape predicts the inner one; the data cannot rule out a perfect match (the interval holds 1)"
    return "the outer shape predicts the inner one in part: the interval excludes both 0 and 1"


def _replay(args: argparse.Namespace) -> int:
    from .fitting import replay_log
    from .io.outputs import claimed_folder

    with claimed_folder(args.out, "replay", args.force):
        rows = replay_log(args.log, args.out, every=args.every, progress=not args.quiet)
    last = rows[-1]
    print(f"replayed {len(rows)} steps of {args.log}; last step {last['step']}: similarity {last['similarity']:.3f}, "
          f"uncertainty {last['uncertainty']:.4g}, Hausdorff {last['hausdorff'] * 100:.2f} cm")
    print(f"wrote records.csv, records.json and transition.png to {args.out}")
    return 0


def _import_bag(args: argparse.Namespace) -> int:
    from .io.datasets import save_dataset
    from .models.estimator import EstimatorSettings
    from .io.rosbag import BagTopics, import_bag

    def numbers(text: str | None, n: int, what: str):
        if text is None:
            return None
        try:
            v = [float(p) for p in text.replace(",", " ").split()]
        except ValueError:
            v = []
        if len(v) != n:
            raise ValueError(f"{what}: expected {n} numbers, got {text!r}")
        return v

    from .io.outputs import check_new_file

    _not_the_recording(args.bag, args.out)
    out = check_new_file(args.out, args.force, "--out")       # before the (long) import
    window = None
    if args.start is not None or args.end is not None:      # an open end: later than any recording
        window = (0.0 if args.start is None else args.start, 1e12 if args.end is None else args.end)
    tool = numbers(args.tool_offset, 3, "--tool-offset")
    crop = numbers(args.crop, 6, "--crop")
    topics = BagTopics(cloud=args.cloud, wrench=args.wrench, joints=args.joints, tf=tuple(args.tf),
                       tactile=args.tactile_topic)
    calibration = None
    if args.tactile_topic is not None:
        from .sensors.tactile import DIGIT_CALIBRATION, TactileCalibration

        calibration = TactileCalibration(
            pitch=DIGIT_CALIBRATION.pitch if args.tactile_pitch is None else args.tactile_pitch,
            gel_thickness=DIGIT_CALIBRATION.gel_thickness if args.tactile_gel is None else args.tactile_gel,
            contact_depth=(DIGIT_CALIBRATION.contact_depth if args.tactile_contact_depth is None
                           else args.tactile_contact_depth))
    ds = import_bag(args.bag, topics=topics, base_frame=args.base_frame, camera_transform=args.camera_transform,
                    tool_offset=tool, tip_radius=args.tip_radius, contact_force=args.contact_force,
                    contact_spacing=args.contact_spacing, max_gap=args.max_gap,
                    settings=_estimator_overrides(args).apply(EstimatorSettings.preset(args.settings)),
                    crop=None if crop is None else [crop[:3], crop[3:]],
                    time_window=window, tactile_calibration=calibration, tactile_transform=args.tactile_transform,
                    camera_bound=args.camera_bound, camera_mount=args.camera_mount)
    path = save_dataset(ds, out, overwrite=args.force)
    c = ds.meta["counts"]
    frames = ", ".join(ds.meta["camera_frames"]) or "none"
    print(f"{args.bag}: {c['wrench']} wrench samples, {c['joint_states']} joint states, {c['clouds']} cloud(s) with "
          f"{c['cloud_points']} finite points in {frames} -> {ds.meta['frame']}")
    print(f"inner: {c['contacts']} contacts (|F| >= {args.contact_force:g} N), {c['free_space']} free-space points; "
          f"outer: {c['outer_surface']} surface + {c['outer_free_space']} free-space points "
          f"({_voxels_text(ds.meta['voxel_size'])})")
    if args.tactile_topic is not None:
        print(f"pad {args.tactile_topic}: {c['pad_frames']} frames, {c['pad_frames_used']} at contacts -> "
              f"{c['patch_surface']} surface + {c['patch_free_space']} free-space points "
              f"({c['pad_frames_out_of_contact']} out of contact, {c['pad_frames_untouched']} with no pixel pressed)")
    if "camera_corrections" in ds.meta:
        from .sensors.extrinsics import misfit_text

        record = ds.meta["camera_corrections"]
        moved = record.get("mount") or record["captures"][0]
        under = sum(c["contacts"] for c in record["captures"])
        who = f"camera on {record['mount_frame']}" if record.get("mount") else "camera"
        print(f"{who}: moved {moved['size_mm']:.1f} mm and {moved['angle_deg']:.2f} deg to agree with the touches "
              f"({under} contacts under its view; {misfit_text(record)})" if record["enough"] else
              f"{who}: not corrected (too few contacts under its view); as the calibration places it")
    print(f"wrote {path}; next: gpioius fit {path} --out outputs/fit")
    return 0


def _voxels_text(voxel) -> str:
    return "every camera point" if not voxel else f"{voxel * 100:g} cm voxels"


def _not_the_recording(bag: str, out: str) -> None:
    """Refuse an ``--out`` that is the recording itself, or a file inside a bag's folder (``--force`` replaced the
    recording with its own dataset)."""
    import os

    src, dst = os.path.realpath(bag), os.path.realpath(out)
    if dst == src or (os.path.isdir(src) and dst.startswith(src.rstrip(os.sep) + os.sep)):
        raise ValueError(f"--out: {out} is {'the recording' if dst == src else 'inside the recording'} {bag}; write "
                         "the dataset elsewhere (--force never replaces the input)")


def _export(args: argparse.Namespace) -> int:
    from .io.export import export_run

    if args.mcap:
        from .io.foxglove import export_mcap

        if args.mesh or args.outer or args.step is not None:
            raise ValueError("export: --mcap writes every step; it does not combine with --mesh, --outer or --step")
        info = export_mcap(args.run, args.mcap, resolution=args.resolution, force=args.force)
        print(f"wrote {info['messages']} messages ({info['steps']} steps) with Foxglove schemas to {info['path']}")
        return 0
    info = export_run(args.run, args.mesh, outer=args.outer, step=args.step, resolution=args.resolution,
                      force=args.force)
    size = f" ({info['vertices']} vertices, {info['faces']} faces)" if "vertices" in info else ""
    for key in ("inner", "outer"):
        if info[key]:
            at = "" if info["step"] is None else f" at step {info['step']}"
            print(f"wrote the {key} estimate{at} to {info[key]}{size if key == 'inner' else ''}")
    return 0


def _view(args: argparse.Namespace) -> int:
    from .viewer import serve

    serve(args.run, port=args.port, open_browser=not args.no_browser, resolution=args.resolution, host=args.host,
          allow_hosts=args.allow_host)
    return 0


def _world_name(text: str) -> str:
    """A world's current name from any name it has had ("3d" and "penalty" are "forcefield" now)."""
    from .exploration.registry import canonical_world_name

    name = canonical_world_name(text)
    if name != text:
        print(f"gpioius: note: world {text!r} is called {name!r} now", file=sys.stderr)
    return name


def _world_of(**capabilities):
    """An argparse type for a registered world's name whose entry has ``capabilities`` (``simulated=True``): only
    the named world's module is imported to ask (MuJoCo's takes a second), all of them when the name is refused."""
    from .exploration.registry import world_entry, world_names

    def parse(text: str) -> str:
        entry = _argument(world_entry, _world_name(text))
        if any(getattr(entry, k) != v for k, v in capabilities.items()):
            raise argparse.ArgumentTypeError(f"the {entry.name} world does not apply here; choose among "
                                             f"{world_names(**capabilities)}")
        return entry.name

    parse.__name__ = "world"
    return parse


def _objects_of(world: str) -> tuple:
    """The built-in objects of a registered world."""
    from .exploration.registry import world_entry

    return world_entry(world).object_names


def _robot_study_objects() -> tuple:
    """The objects of the robot study in 3-D (Sec. VI: E-H), those ``simulate3d`` runs."""
    from .studies.simulate3d import OBJECTS

    return tuple(OBJECTS)


def _presets(dimension: int | None = None) -> list[str]:
    """The estimator's presets by name (``EstimatorSettings``: default, paper, paper-2d); with ``dimension=3``,
    the 3-D worlds' settings (default, paper, gap)."""
    from .models.estimator import PRESETS
    from .sim.presets import SETTINGS

    return list(PRESETS) if dimension is None else list(SETTINGS)


def _covers() -> list[str]:
    """The covers of an object set's objects (``sim.objectsets.COVERS``: tight, wide, uneven, hanging)."""
    from .sim.objectsets import COVERS

    return list(COVERS)


def _learns() -> list[str]:
    """What a fit can learn (K_t; also the length; also the noise)."""
    from .models.estimator import LEARN

    return list(LEARN)


def _sweep_modes() -> tuple:
    from .studies.study import sweep_modes

    return sweep_modes()


def _names(registry) -> str:
    """What users can type for a registry's entries, for a help text."""
    return ", ".join(registry.choices())


def _number(text: str, name: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{name}: not {what}: {text!r}") from None


def _argument(check, value):
    """``check(value)`` as an argparse type: its ValueError becomes the option's error message."""
    try:
        return check(value)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _voxel(text: str) -> float:
    from .exploration.observations import check_voxel

    return _argument(check_voxel, _number(text, "voxel", "a number of metres"))


DEVICE_HELP = ("where the GP arithmetic runs: cpu, or cuda for a GPU (float64 either way; the robot, the world and "
               "the records stay on the CPU; docs/performance.md)")
OUTER_TOL_HELP = ("visual-tactile runs with a truncated outer basis dropping a PSD part of trace <= OUTER_TOL * "
                  "sigma^2 (an approximation for thousands of camera points, e.g. 1e-3 with --voxel 0.01; "
                  "docs/performance.md); default: exact")


def _device(text: str) -> str:
    from .core.validation import as_device

    return str(_argument(as_device, text))


def _outer_tol(text: str) -> float:
    from .core.validation import as_float

    return _argument(lambda v: as_float(v, "outer_tol", positive=True), _number(text, "outer_tol", "a number"))


def _length(option: str):
    """An argparse type for a length [m]: positive, at most 20 m (a larger one was meant in mm or cm)."""
    from .core.validation import as_length

    def parse(text: str) -> float:
        return _argument(lambda v: as_length(v, f"--{option}"), _number(text, option, "a number of metres"))

    parse.__name__ = option          # argparse names the type in its messages
    return parse


def _kernel_length(option: str):
    """An argparse type for a kernel's length [m], in the one range every door takes (1 mm to 10 m)."""
    from .core.validation import as_kernel_length

    def parse(text: str) -> float:
        return _argument(lambda v: as_kernel_length(v, f"--{option}"), _number(text, option, "a number of metres"))

    parse.__name__ = option
    return parse


def _kernel_names() -> str:
    """The kernel names the command line takes, from the kernel registry (registered kinds and their aliases)."""
    from .kernels import KERNELS

    return _names(KERNELS)


def _touch_name(text: str) -> str:
    """An argparse type for a touch model's name (checked against the registry; its registered name returned)."""
    from .exploration.touch import TOUCH_MODELS

    return _argument(TOUCH_MODELS.resolve, text)


def _kernel_name(text: str) -> str:
    """An argparse type for a kernel's name (checked against the kernel registry)."""
    from .kernels import kernel_kind

    _argument(kernel_kind, text)
    return text                      # as typed: a study folder records the name its command line gave


def _noise(text: str) -> float:
    """An argparse type for sigma^2, in the one range every door takes."""
    from .core.validation import as_noise

    return _argument(lambda v: as_noise(v, "--noise"), _number(text, "noise", "a number"))


def _voxel_or_auto(text: str):
    """An argparse type for the camera's voxel edge [m] (0: every point), or "auto" (None: the settings' rule)."""
    return None if text == "auto" else _voxel(text)


def _assignment(text: str):
    """An argparse type for ``--estimator KEY=VALUE``: the pair, its key and value checked at once."""
    from .models.overrides import EstimatorOverrides

    _argument(lambda t: EstimatorOverrides.from_assignments([t]), text)
    return text


def _add_estimator_arguments(parser: argparse.ArgumentParser, default: str) -> None:
    """The estimator's flags, declared once for every sub-command that takes them (``study``, ``fit``,
    ``import-bag``): each read into one :class:`~torch_gpioius.models.overrides.EstimatorOverrides` by
    :func:`_estimator_overrides` and checked by the one check its setting has. ``default`` says what each
    replaces ("each world's own", "the settings'")."""
    group = parser.add_argument_group("the estimator's settings")
    group.add_argument("--kernel", default=None, type=_kernel_name,
                       help=f"the kernel: {_kernel_names()} (imq: the paper's inverse multiquadric; a kernel "
                            "registered with register_kernel by its kind; without --lengthscale at the length the "
                            f"settings' rule or kernel gives); default: {default}")
    group.add_argument("--lengthscale", type=_kernel_length("lengthscale"), default=None,
                       help="the kernel's length scale [m] (the paper's theta for the inverse multiquadric; with "
                            "--learn length or all, where the learning starts; the length rule dropped); default: "
                            f"{default}")
    group.add_argument("--theta", type=_kernel_length("theta"), default=None,
                       help="deprecated: the paper's inverse multiquadric of this length (--kernel imq --lengthscale "
                            "THETA)")
    group.add_argument("--noise", type=_noise, default=None,
                       help=f"sigma^2 (with --learn all, where the learning starts); default: {default}")
    group.add_argument("--learn", default=None, choices=_learns(),
                       help="what is learned: task (K_t alone, the paper's), length (also the kernel's length) or "
                            "all (the length and the noise too), by the exact marginal likelihood; default: "
                            f"{default}")
    group.add_argument("--voxel", type=_voxel_or_auto, default=None,
                       help="edge of the camera's voxels [m] (0 keeps every camera point; auto: the settings' rule, "
                            f"a tenth of the object within 2-5 cm by default); default: {default}")
    group.add_argument("--estimator", action="append", default=None, type=_assignment, metavar="KEY=VALUE",
                       help="any other estimator setting, repeatable: noise, learn, restart_every, kernel, "
                            "lengthscale, voxel, or labels.FIELD for a field of the labelling policy (e.g. "
                            "labels.ray_smoothing=none, labels.vision_inside=0.03, labels.cover_offset=true); none "
                            "is None")


def _estimator_overrides(args: argparse.Namespace):
    """The estimator's flags (:func:`_add_estimator_arguments`) as one
    :class:`~torch_gpioius.models.overrides.EstimatorOverrides`.

    Raises:
        ValueError: a setting given twice (by its flag and by ``--estimator``), or ``--theta`` beside ``--kernel``
            or ``--lengthscale``.
    """
    from .models.overrides import EstimatorOverrides

    if args.theta is not None:
        if args.kernel is not None or args.lengthscale is not None:
            raise ValueError("--theta (deprecated) names a kernel and its length; give --kernel and --lengthscale "
                             "instead, not both")
        warnings.warn("--theta is the paper's name for the inverse multiquadric's length: give --kernel imq "
                      "--lengthscale", DeprecationWarning)
    flags = {"kernel": "imq" if args.theta is not None else args.kernel,
             "lengthscale": args.theta if args.theta is not None else args.lengthscale,
             "noise": args.noise, "learn": args.learn, "voxel": args.voxel}
    flags = {k: v for k, v in flags.items() if v is not None}
    given = EstimatorOverrides.from_assignments(args.estimator or ()).to_dict()
    twice = sorted(set(flags) & set(given))
    if twice:
        raise ValueError(f"--estimator: {', '.join(twice)} given by its own flag too; give it once")
    return EstimatorOverrides.from_dict({**flags, **given}, "the estimator's flags")


def _camera_error(text: str):
    """An argparse type for a simulated camera error ("6mm,1deg"), as its canonical text."""
    from .sensors.simulated.camera import CameraError

    return str(_argument(CameraError.parse, text))


def _views(text: str):
    """An argparse type for camera views: comma-separated names, a count (1-3) or "paper"."""
    from .sim.presets import as_views

    text = text.strip()
    return _argument(as_views, int(text) if text.isdigit() else tuple(v.strip() for v in text.split(","))
                     if "," in text else text)


def _metrics_every(text: str):
    """An argparse type for ``--metrics-every``: a number of steps or "schedule"."""
    from .studies.study_plan import checked_metrics_every

    return _argument(checked_metrics_every, text.strip())


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


class _Formatter(argparse.ArgumentDefaultsHelpFormatter):
    """Shows each option's default once: not when its help already says it, nor for options without one."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "default" in text.lower() or action.default in (None, False, argparse.SUPPRESS) or not action.option_strings:
            return text
        return text + " (default: %(default)s)"


def _force(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--force", action="store_true", help=f"write even if {what} (files of the same names are replaced)")


def _add_simulate(sub, common, fmt) -> None:
    """The ``simulate`` sub-command."""
    sim = sub.add_parser("simulate", parents=[common], formatter_class=fmt,
                         help="run the paper's 2-D study (objects A-D, both modes) and write figures",
                         description="Reproduce the paper's 2-D study: sliding exploration of objects A-D with "
                                     "visual-tactile GPIOIS and tactile-only GPIS; writes Fig. 4/5-like figures, "
                                     "per-step records (CSV/JSON) and a summary table.")
    sim.add_argument("--object", default="all", choices=["all", *_objects_of("planar")], help="object(s) to explore")
    sim.add_argument("--out", default="outputs/study2d", help="output folder")
    sim.add_argument("--max-steps", type=int, default=400, help="cap on planning steps per run")
    sim.add_argument("--smoke", action="store_true", help="12 steps per run, claims not judged (CI)")
    sim.add_argument("--quiet", action="store_true", help="no progress output")
    _force(sim, "--out holds files that `gpioius simulate` did not write")
    sim.set_defaults(func=_simulate)


def _add_simulate3d(sub, common, fmt) -> None:
    """The ``simulate3d`` sub-command."""
    s3 = sub.add_parser("simulate3d", parents=[common], formatter_class=fmt,
                        help="run the robot study in simulation (objects E-H, both modes)",
                        description="Sec. VI in simulation: objects E-H (arm and torso under tight and loose "
                                    "covers) explored by a simulated UR5 with a fingertip force sensor, after one "
                                    "capture of a simulated depth camera; visual-tactile GPIOIS vs tactile-only "
                                    "GPIS until 1.5 m of travel. Writes Fig. 9/10-like figures, records, logs and "
                                    "a summary table with the Sec. VI-B claims as measured.")
    s3.add_argument("--object", default=None, choices=["all", *_robot_study_objects()],
                    help="object(s) to explore (default: all, or none when --scene is given)")
    s3.add_argument("--scene", default=None,
                    help="comma-separated scene files (TOML: your own mesh, cover, approach; "
                         "docs/tutorials/your-object.md)")
    s3.add_argument("--world", default="forcefield", type=_world_of(simulated=True, dimension=3),
                    help="a simulated 3-D world: forcefield (a static force-field cover), mujoco (cloth and foam on "
                         "MuJoCo's contact physics), or one registered with register_world (docs/architecture.md)")
    s3.add_argument("--out", default="outputs/study3d", help="output folder")
    s3.add_argument("--max-travel", type=_length("max-travel"), default=1.5, help="fingertip travel per run [m]")
    s3.add_argument("--metrics-every", type=int, default=5, help="surface metrics every k steps")
    s3.add_argument("--touch", default="point", type=_touch_name,
                    help="a registered touch model: point (the fingertip's contact, the paper), patch (a DIGIT-like "
                         "gel pad's depth map at each contact, both 3-D worlds), or one registered with "
                         "register_touch_model")
    s3.add_argument("--outer-tol", type=_outer_tol, default=None, help=OUTER_TOL_HELP)
    s3.add_argument("--device", type=_device, default=None, help=DEVICE_HELP + " (default: cpu)")
    s3.add_argument("--smoke", action="store_true", help="6 cm of travel on coarse meshes, claims not judged (CI)")
    s3.add_argument("--quiet", action="store_true", help="no progress output")
    _add_estimator_arguments(s3, "each scene's own (the paper's for E-H)")
    _force(s3, "--out holds files that `gpioius simulate3d` (of this world) did not write")
    s3.set_defaults(func=_simulate3d)


def _add_study(sub, common, fmt) -> None:
    """The ``study`` sub-command."""
    sw = sub.add_parser("study", parents=[common], formatter_class=fmt,
                        help="objects x modes x seeds, on Ray when installed; statistics, paired tests, figures",
                        description="Run every (object, mode, seed) as one task (a Ray task when the 'ray' extra is "
                                    "installed, else in-process), skip runs already on disk, and write runs.csv, "
                                    "summary.json/md (medians, 95 % intervals, paired VT - T with Wilcoxon p-values, "
                                    "the paper's claims judged with stated rules) and figures with bands.")
    sw.add_argument("--world", default="planar", type=_world_of(simulated=True),
                    help="a simulated world: planar (2-D objects A-D), forcefield or mujoco (3-D objects E-H), or one "
                         "registered with register_world (docs/architecture.md)")
    sw.add_argument("--objects", default=None,
                    help="comma-separated object names (default: the world's objects, A-D in 2d and E-H in 3-D), or "
                         "an object set in the forcefield world: primitives:0-49, pybullet-random:0-49 (their "
                         "-lying families: turned onto their side), pybullet:duck,teddy or folder:PATH (each object "
                         "sized 8-25 cm, on the table)")
    sw.add_argument("--metrics-every", default=None, type=_metrics_every,
                    help="measure the estimate every K steps, or 'schedule': at 10, 25 and 50 %% of the travel, a "
                         "stop and the end only (3-D worlds; the fractions the summary reports, at a fraction of "
                         "the cost); default: every 5 steps in the 3-D worlds, every step in 2-D; one per --out "
                         "folder")
    sw.add_argument("--cover", default=None, choices=_covers(),
                    help="the cover of an object set's objects: tight (8 mm), wide (4 cm), uneven (5 mm on one side "
                         "to 5 cm on the other) or hanging (5 mm on top, hanging to the table); default tight; one "
                         "per --out folder")
    sw.add_argument("--scenes", default=None,
                    help="comma-separated scene files (TOML; docs/tutorials/your-object.md) run as objects; with "
                         "--scenes and no --objects only the scenes run (3-D worlds)")
    sw.add_argument("--modes", default="visual-tactile,tactile",
                    help=f"comma-separated: {', '.join(_sweep_modes())} (a mode, or a mode with a registered "
                         "evidence policy that serves it)")
    sw.add_argument("--seeds", type=_positive_int, default=10,
                    help="seeds per object and mode (seed 0 = unperturbed; at most 10000)")
    sw.add_argument("--out", default="outputs/study", help="output folder")
    sw.add_argument("--workers", type=_positive_int, default=None, help="parallel runs (default: the CPU count)")
    sw.add_argument("--address", default=None, help="join an existing Ray cluster (e.g. ray://host:10001 or auto)")
    sw.add_argument("--max-travel", type=_length("max-travel"), default=None,
                    help="travel budget per run [m] (3-D worlds)")
    sw.add_argument("--max-steps", type=int, default=None, help="cap on planning steps per run")
    sw.add_argument("--touch", default="point", type=_touch_name,
                    help="a registered touch model: point (the fingertip's contact), patch (a gel pad's depth map, "
                         "3-D worlds) or one registered with register_touch_model; one per --out folder")
    sw.add_argument(
        "--outer-tol", type=_outer_tol, default=None, help=OUTER_TOL_HELP + "; one setting per --out folder"
    )
    sw.add_argument("--device", type=_device, default=None, help=DEVICE_HELP + " (default: cpu)")
    sw.add_argument("--settings", default=None, choices=_presets(3),
                    help="the 3-D worlds' settings, for scene files and built-in objects alike: default (three "
                         "camera views, voxels a tenth of the body, a Matern-5/2 a fifth of it long, inside points), "
                         "paper (one fixed camera, 5 cm voxels, the inverse multiquadric), gap (an experiment: the "
                         "defaults with a transfer that knows the cover's gap, docs/method-notes.md section 16) or "
                         "gapfield (another: that gap a place at a time, section 18); "
                         "default: each file's own, the paper's for the built-in objects; one per --out folder")
    sw.add_argument("--views", type=_views, default=None,
                    help="the 3-D worlds' simulated camera views in place of the settings': comma-separated names "
                         "(fixed, mirrored, wrist), a count (1-3) or paper (the fixed camera alone); one per --out "
                         "folder")
    sw.add_argument("--camera-error", type=_camera_error, default=None, metavar="SIZES",
                    help="the 3-D worlds' simulated cameras off by a calibration error of these sizes, e.g. "
                         "6mm,1deg (each view of each run draws its direction and axis from its seed; the records "
                         "say what was applied), and sensing worse than the camera model's: 3x (its depth noise "
                         "tripled), 20%% (a fifth of the pixels lost at random), 20%%holes (a fifth of the image lost "
                         "in blocks, anew each capture); e.g. 6mm,1deg,2x,20%%holes; default: none; one per --out "
                         "folder")
    sw.add_argument("--camera-bound", type=_camera_error, default=None, metavar="SIZES",
                    help="the visual-tactile runs correct each camera view's capture from their contacts, by at most "
                         "these sizes, e.g. 12mm,2deg (each record: camera_corrections); default: as captured; one per "
                         "--out folder")
    _add_estimator_arguments(sw, "each world's own; one per --out folder")
    sw.add_argument("--smoke", action="store_true", help="tiny runs, claims not judged (CI)")
    sw.add_argument("--quiet", action="store_true", help="no progress output")
    _force(sw, "--out holds files that are not a study of this world")
    sw.set_defaults(func=_study)


def _add_fit(sub, common, fmt) -> None:
    """The ``fit`` sub-command."""
    fit = sub.add_parser("fit", parents=[common], formatter_class=fmt,
                         help="learn K_t on a dataset or log; save a checkpoint and a figure",
                         description="Fit GPIOIS (GPIS if there are no outer observations) on a torch_gpioius "
                                     "dataset or exploration log (docs/data-format.md): prints K_t, the correlation, "
                                     "the paper's similarity and the marginal likelihood; with --out saves model.pt, "
                                     "fit.png and fit.json.")
    fit.add_argument("dataset", help="dataset or exploration log file (.gpioius), or your contacts as a CSV "
                                     "(x,y[,z],label[,step]; docs/tutorials/own-data.md)")
    fit.add_argument(
        "--cloud",
        action="append",
        default=None,
        help="with a contacts CSV: the camera's point cloud (PLY, PCD, XYZ, NPZ) in the same frame; repeat "
        "it for several captures (each with its own --camera-origin, in the same order)",
    )
    fit.add_argument("--units", default="m", choices=["m", "cm", "mm"], help="units of the CSV and the cloud")
    fit.add_argument("--camera-bound", type=_camera_error, default=None, metavar="SIZES",
                     help="with clouds and their --camera-origin: correct each capture's pose (its camera's "
                          "calibration) from the contacts and the other captures, by at most these sizes, e.g. "
                          "6mm,1deg (fit.json: camera_corrections; a large one is warned of); default: as given")
    fit.add_argument("--table", type=float, default=None, metavar="Z",
                     help="with --camera-bound: the height of the table the object stands on (z, in --units), "
                          "known to the robot: each capture's view of the table around the object is held to it as "
                          "well (give the clouds uncropped); default: no table")
    fit.add_argument("--contact-spacing", type=_length("contact-spacing"), default=None,
                     help="with a contacts CSV: drop rows within this distance [m] of an earlier row of their kind "
                          "(contacts, free space, inside points); an exact fit's memory grows with the square of the "
                          "observations (default: every row)")
    fit.add_argument("--quiet", action="store_true", help="no progress lines during a long fit")
    fit.add_argument("--camera-origin", action="append", default=None, metavar='"X Y Z"',
                     help="the camera's optical centre in the files' frame and units: adds the free space in front "
                          "of the seen surface (without it the model knows where the cover is, not which side is "
                          "empty); one per --cloud")
    fit.add_argument("--out", default=None, help="folder for model.pt (checkpoint), fit.png and fit.json")
    fit.add_argument("--settings", default=None, choices=_presets(),
                     help="the estimator's settings (kernel, sigma^2, labels, voxels): default (this library's, "
                          "measured best on shapes nobody tuned to), paper (the robot experiment's), or the "
                          "experiments gap and gapfield (the defaults with the outer mean standing for the cover's "
                          "gap the contacts measure, one gap or a field of them: for a cover standing more than 3 cm "
                          "off); default: 'default' for a contacts CSV, the file's own for a .gpioius file")
    fit.add_argument("--mesh", default=None, metavar="EST.ply",
                     help="write the inner estimate {mu_in = 0} there (PLY, OBJ, STL, OFF, GLB; SVG, DXF in 2-D)")
    fit.add_argument("--outer-mesh", default=None, metavar="OUT.ply", help="write the outer estimate there")
    fit.add_argument("--resolution", type=_length("resolution"), default=None,
                     help="grid of the estimate [m] (default: its figure 5 mm in 2-D and 2 cm in 3-D, its meshes "
                          "5 mm and 1 cm, as export's)")
    _add_estimator_arguments(fit, "the settings'")
    _force(fit, "--out holds files that `gpioius fit` did not write")
    fit.set_defaults(func=_fit)


def _add_replay(sub, common, fmt) -> None:
    """The ``replay`` sub-command."""
    rep = sub.add_parser("replay", parents=[common], formatter_class=fmt,
                         help="re-run the estimation of an exploration log step by step",
                         description="Rebuild the model after each logged step, re-learn K_t, and write per-step "
                                     "records (similarity, uncertainty, Hausdorff when the scene is known) and a "
                                     "figure of their transitions (transition.png).")
    rep.add_argument("log", help="exploration log (.gpioius) written by explore(log=...) or `gpioius simulate`")
    rep.add_argument("--out", default="outputs/replay", help="output folder")
    rep.add_argument("--every", type=_positive_int, default=1, help="replay every k-th step (the last always)")
    rep.add_argument("--quiet", action="store_true", help="no progress output")
    _force(rep, "--out holds files that `gpioius replay` did not write")
    rep.set_defaults(func=_replay)


def _add_import_bag(sub, common, fmt) -> None:
    """The ``import-bag`` sub-command."""
    bag = sub.add_parser(
        "import-bag",
        parents=[common],
        formatter_class=fmt,
        help="turn a ROS 2 bag (MCAP or sqlite3) into a .gpioius dataset",
        description="Read a ROS 2 bag recorded on a UR5 with a fingertip force sensor and a depth "
        "camera (the 'rosbag' extra, no ROS install needed): fingertip positions by the "
        "UR5's forward kinematics at the interpolated joint states, |F| >= 1 N a contact, "
        "free space below, point clouds into the base frame through tf and voxel-averaged. "
        "Writes a dataset for `gpioius fit` and `gpioius replay` (docs/tutorials/rosbag.md).",
    )
    bag.add_argument("bag", help="bag folder (with metadata.yaml) or .mcap/.db3 file")
    bag.add_argument("--out", required=True, help="dataset to write (.gpioius)")
    bag.add_argument("--cloud", default="/camera/depth/points", help="sensor_msgs/PointCloud2 topic")
    bag.add_argument("--wrench", default="/wrench", help="geometry_msgs/WrenchStamped topic of the fingertip sensor")
    bag.add_argument("--joints", default="/joint_states", help="sensor_msgs/JointState topic of the UR5")
    bag.add_argument("--tf", nargs="*", default=["/tf_static", "/tf"], help="tf2_msgs/TFMessage topics")
    bag.add_argument("--base-frame", default="base", help="the robot's base frame in tf")
    bag.add_argument("--camera-transform", default=None,
                     help="T_base_cloudframe as 'x y z qx qy qz qw' (replaces the tf lookup)")
    bag.add_argument("--camera-bound", type=_camera_error, default=None, metavar="SIZES",
                     help="correct the camera's pose (its calibration or tf) from the contacts, by at most these "
                          "sizes, e.g. 6mm,1deg: a camera fixed in the base frame (the dataset records the "
                          "correction; a large one is warned of); default: as the calibration places it")
    bag.add_argument("--camera-mount", default=None, metavar="FRAME",
                     help="with --camera-bound: the tf frame of the link the camera rides on (a wrist camera's tool0): "
                          "one hand-eye correction in that frame for every cloud; default: fixed in the base frame")
    bag.add_argument("--tool-offset", default="0 0 0", help="fingertip centre in the flange frame 'x y z' [m]")
    bag.add_argument("--tip-radius", type=float, default=0.0, help="fingertip radius [m] (contact = centre - r F/|F|)")
    bag.add_argument("--contact-force", type=float, default=1.0, help="|F| of a contact [N] (paper: 1.0)")
    bag.add_argument("--contact-spacing", type=float, default=0.005, help="thin contacts to this spacing [m]")
    bag.add_argument("--max-gap", type=float, default=0.1, help="longest joint-state gap to interpolate over [s]")
    bag.add_argument("--settings", default="default", choices=["default", "paper"],
                     help="the estimator's settings the dataset records for fit (kernel, sigma^2, free space, voxels) "
                          "and its labels: inside points behind the contacts, along the measured forces (none behind "
                          "the seen surface: a bag's clouds come from a moving camera)")
    bag.add_argument("--crop", default=None, help="keep cloud points in 'xmin ymin zmin xmax ymax zmax' [m]")
    bag.add_argument("--start", type=float, default=None,
                     help="import from this many seconds after the first wrench sample (default: the beginning)")
    bag.add_argument("--end", type=float, default=None,
                     help="import up to this many seconds after the first wrench sample (default: the end)")
    bag.add_argument("--tactile-topic", default=None,
                     help="sensor_msgs/Image depth topic of a gel pad at the fingertip (DIGIT, GelSight): its frames "
                          "at contacts become patches")
    bag.add_argument("--tactile-pitch", type=float, default=None, help="the pad's pixel pitch [m] (default: DIGIT's)")
    bag.add_argument("--tactile-gel", type=float, default=None, help="the gel's thickness [m] (default: DIGIT's)")
    bag.add_argument("--tactile-contact-depth", type=float, default=None,
                     help="indentation [m] at which a pixel is a contact (default: DIGIT's)")
    bag.add_argument("--tactile-transform", default=None,
                     help="T_tool_pad: the pad frame in the fingertip frame, 'x y z qx qy qz qw' (default: identity)")
    _add_estimator_arguments(bag, "the settings' (the voxel: a tenth of the --crop box, 2-5 cm, by default; 5 cm "
                                  "without a crop box)")
    _force(bag, "--out exists")
    bag.set_defaults(func=_import_bag)


def _add_export(sub, common, fmt) -> None:
    """The ``export`` sub-command."""
    ex = sub.add_parser(
        "export",
        parents=[common],
        formatter_class=fmt,
        help="write the estimated surfaces of a run as PLY/OBJ/STL/GLB meshes (SVG/DXF curves in 2-D), or the "
        "whole run as MCAP for Foxglove",
        description="Rebuild the model of a log or dataset at a step with the run's own learned K_t and "
        "write {mu = 0} through trimesh, coloured by the posterior variance (PLY meshes "
        "also carry a 'variance' vertex property).",
    )
    ex.add_argument("run", help="exploration log or dataset (.gpioius)")
    ex.add_argument("--mesh", default=None, help="file for the inner estimate (.ply .obj .stl .glb .off; 2-D: .svg "
                                                 ".dxf .ply .obj)")
    ex.add_argument("--outer", default=None, help="file for the outer estimate (visual-tactile runs)")
    ex.add_argument("--step", type=int, default=None, help="step to export (default: the last)")
    ex.add_argument("--mcap", default=None, help="write the whole run as MCAP with Foxglove schemas (the 'foxglove' "
                                                 "extra) for scrubbing in Foxglove")
    ex.add_argument("--resolution", type=float, default=None, help="grid spacing [m] (default 5 mm 2-D, 1 cm 3-D)")
    _force(ex, "an output file exists (a link there is replaced, never followed)")
    ex.set_defaults(func=_export)


def _registered(args: argparse.Namespace) -> int:
    from .exploration.registry import registered_tables

    tables = registered_tables()
    for kind in ([args.kind] if args.kind else tables):
        print(f"## {kind}\n\n{tables[kind]}\n")
    return 0


def _add_registered(sub, fmt) -> None:
    """The ``registered`` sub-command."""
    reg = sub.add_parser("registered", formatter_class=fmt,
                         help="list the kernels, worlds, touch models, evidence policies and sensors by name",
                         description="Print each registry as a Markdown table: the names (and aliases) the command "
                                     "line, scene files and studies take, with each entry's capabilities; those "
                                     "registered by code imported before (a plugin) are listed too.")
    reg.add_argument("kind", nargs="?", default=None, choices=["kernels", "worlds", "touch", "evidence", "sensors"],
                     help="one registry (default: all)")
    reg.set_defaults(func=_registered)


def _add_view(sub, common, fmt) -> None:
    """The ``view`` sub-command."""
    vw = sub.add_parser("view", parents=[common], formatter_class=fmt,
                        help="serve an interactive 3-D page of a run (viser): steps, contacts, path, estimate",
                        description="Serve a local web page (the 'viewer' extra) showing a log, a dataset or every log "
                                    "of a study folder: the point cloud, contacts and free space, the path, the "
                                    "estimated inner surface coloured by its variance, the true shapes when known, "
                                    "and the similarity over the steps, with a step slider. Ctrl-C stops it.")
    vw.add_argument("run", help="exploration log, dataset (.gpioius) or study folder (with logs/)")
    vw.add_argument("--port", type=int, default=8080, help="TCP port of the page (0: any free port)")
    vw.add_argument("--host", default="127.0.0.1",
                    help="interface to serve on; 0.0.0.0 serves every interface (other machines can then connect; "
                         "a warning says so)")
    vw.add_argument("--allow-host", action="append", default=[], metavar="NAME",
                    help="a host name, besides this machine's own, under which browsers may open the page (a DNS "
                         "alias, a reverse proxy); repeatable")
    vw.add_argument("--no-browser", action="store_true", help="do not open a browser")
    vw.add_argument("--resolution", type=float, default=None, help="grid spacing of the estimate [m]")
    vw.set_defaults(func=_view)


def build_parser() -> argparse.ArgumentParser:
    """The ``gpioius`` argument parser (every help text shows its default once)."""
    from ._version import __version__

    fmt = _Formatter
    parser = argparse.ArgumentParser(prog="gpioius", formatter_class=fmt,
                                     description="Visuo-tactile inner-shape estimation (GPIOIS).")
    parser.add_argument("--version", action="version", version=f"gpioius {__version__}")
    common = argparse.ArgumentParser(add_help=False, formatter_class=fmt)
    common.add_argument("--threads", type=_positive_int, default=1,
                        help="torch threads for the GP arithmetic (1 is fastest on 2 cores under load)")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_simulate(sub, common, fmt)
    _add_simulate3d(sub, common, fmt)
    _add_study(sub, common, fmt)
    _add_fit(sub, common, fmt)
    _add_replay(sub, common, fmt)
    _add_import_bag(sub, common, fmt)
    _add_export(sub, common, fmt)
    _add_view(sub, common, fmt)
    _add_registered(sub, fmt)
    return parser


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings as one line a user can read (``gpioius: warning: ...``), without the library's source line."""
    text = " ".join(str(message).split())
    print(f"gpioius: warning: {text}", file=sys.stderr if file is None else file, flush=True)


def _parse(parser: argparse.ArgumentParser, argv: list[str] | None) -> argparse.Namespace:
    """``parser.parse_args``, except that an unknown option is reported by its command's parser (its usage, not the
    top level's) with the nearest options it has (``--max-travle``: did you mean --max-travel?)."""
    import difflib

    args, extra = parser.parse_known_args(argv)
    if not extra:
        return args
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    sub = action.choices[args.command]
    known = [o for a in sub._actions for o in a.option_strings]
    hints = []
    for token in extra:
        name = token.split("=", 1)[0]
        if name.startswith("-") and not _is_number(name):
            close = difflib.get_close_matches(name, known, n=2, cutoff=0.6)
            if close:
                hints.append(f"{name}: did you mean {' or '.join(close)}?")
    vector = _unquoted_vector(list(argv if argv is not None else sys.argv[1:]), extra)
    if vector:
        hints.append(vector)
    sub.error(f"unrecognized arguments: {' '.join(extra)}" + (f" ({'; '.join(hints)})" if hints else ""))
    raise AssertionError("unreachable")  # pragma: no cover - error() exits


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _unquoted_vector(argv: list[str], extra: list[str]) -> str | None:
    """A hint for an option's several numbers given unquoted (``--camera-origin 0.5 -0.8 0.45`` left ``-0.8 0.45``
    over): the option's numbers go in one quoted argument."""
    if not extra or not all(_is_number(t) for t in extra):
        return None
    try:
        i = argv.index(extra[0])
    except ValueError:
        return None
    j = i - 1
    while j >= 0 and _is_number(argv[j]):
        j -= 1
    if j < 0 or not argv[j].startswith("--"):
        return None
    values = " ".join(argv[j + 1:i] + extra)
    return f"{argv[j]} takes its numbers as one quoted argument: {argv[j]} \"{values}\""


def main(argv: list[str] | None = None) -> int:
    from .core.registry import load_plugins
    from .core.threads import torch_threads

    try:
        load_plugins()                       # before the choices are read from the registries
    except ImportError as exc:
        print(f"gpioius: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    args = _parse(build_parser(), argv)
    try:
        with torch_threads(getattr(args, "threads", 1)), warnings.catch_warnings():
            warnings.showwarning = _one_line_warning
            from .models.gpiois import FitNotConvergedWarning

            # a fit at its iteration cap uses the best K_t found: `fit` says so in its report, other commands keep
            # quiet about it (nothing for a user to act on)
            warnings.simplefilter("ignore", FitNotConvergedWarning)
            return args.func(args)
    except (ValueError, OSError, RuntimeError, ImportError, MemoryError) as exc:
        message = " ".join(str(exc).split())
        print(f"gpioius: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gpioius: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:
        if type(exc).__module__.split(".")[0] == "mujoco":    # MuJoCo's own FatalError (e.g. its arena is full)
            message = " ".join(str(exc).split())
            print(f"gpioius: error: MuJoCo: {message}", file=sys.stderr)
            return 2
        raise


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
