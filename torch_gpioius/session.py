"""``torch_gpioius.explore``: the exploration loop with its crash-safe log and resume plugged in from above.

The loop (:mod:`torch_gpioius.exploration.loop`) knows nothing of files; this module adds the log recorder and the
restore of :mod:`torch_gpioius.io.logs`, which sit above it.
"""

from __future__ import annotations

import os
import warnings

from .exploration.config import LOOSE, ExploreConfig
from .exploration.loop import run
from .exploration.trace import Trace
from .exploration.world import World
from .io.logs import LogRecorder, restore_run
from .models.base import kernel_for_theta
from .models.overrides import loose_keywords, warn_loose

__all__ = ["explore"]


def explore(world: World, mode: str = "visual-tactile", *, settings=None, evidence=None, touch=None,
            step: float | None = None, max_steps: int | None = None, max_travel: float | None = None, stop=None,
            penalty=None, metrics_every: int | str | None = None, metrics_resolution: float | None = None,
            interval_every: int | None = None, regions: int | None = None, stall="default",
            outer_tol: float | None = None, device=None, recorders=(), progress: bool = False,
            log: str | os.PathLike | None = None, resume_from: str | os.PathLike | None = None,
            overwrite: bool = False, **deprecated) -> Trace:
    """Explore ``world`` and record per-step metrics: the same loop for every world.

    Protocol (both modes alike): visual-tactile mode captures one point cloud before exploring (outer surface
    points, y = 0, and the free space in front of them, y = 1; ``policy``). The fingertip approaches along
    ``world.direction`` to the first contact; the approach's free space is inner free space. Then each step plans
    d* (eq. 19, L = V_in + C) at the contact, the world's contact controller executes it, the touch model turns the
    result into observations (a point touch: the contact, y = 0, and the free space crossed, y = 1, thinned, kept
    ``policy.free_space_margin`` from every contact, with earlier samples retracted when a new contact lands
    closer), an evidence policy may gather more, and K_t is re-learned (warm-started). The run stops on the
    world's stop rules (2-D: once around the shape; robot study: 1.5 m of travel), after ``max_steps``, when contact
    is lost, or when the robot refuses a command.

    Every world-specific setting is the world's (``world.defaults``: alpha, stop rules, the estimator's settings it
    suggests for its object; its hardware, camera and range penalty); the arguments below override them for one run.
    The estimator's settings (kernel, sigma^2, labels, voxels, what is learned) are one
    :class:`~torch_gpioius.models.estimator.EstimatorSettings`: ``settings`` gives another whole, or the world's own
    with changes (an :class:`~torch_gpioius.models.overrides.EstimatorOverrides`: any of them, a label's field
    included; docs/reference/settings.md). The keywords ``theta``, ``kernel``, ``noise``, ``policy``, ``learn`` and
    ``restart_every`` of earlier releases (``**deprecated``) still change one of them for one release, through the same
    resolver, with a DeprecationWarning.

    Why this many parameters: each is a separate choice of one run (how it explores, when it stops, what it measures,
    where it computes and logs); the estimator's settings, the part that grows, are one object (``settings``).

    Args:
        world: a :class:`~torch_gpioius.exploration.world.World` (``tg.sim.Scene2D``, ``tg.sim.Scene3D``,
            ``tg.sim.MujocoScene``, ``tg.RobotWorld``, or a user's).
        mode: "visual-tactile" (GPIOIS on vision + touch) or "tactile" (GPIS on touch only).
        evidence: None (the paper's exploration), "taps" (evidence-seeking taps, visual-tactile only; see
            :mod:`torch_gpioius.exploration.evidence`), "reach" (every 15 steps, lift off and touch the least
            certain surface elsewhere, reached through free space; 3-D, either mode; see
            :mod:`torch_gpioius.exploration.reach`), or an evidence policy object.
        touch: "point" (a fingertip force sensor, the paper's) or a touch model object
            (:mod:`torch_gpioius.exploration.touch`).
        step: alpha, the planned step [m], in (0, 0.1].
        settings: the estimator's settings (an :class:`~torch_gpioius.models.estimator.EstimatorSettings` or a
            preset's name: "default", "paper", "paper-2d"; a preset's voxel rule sized to the world's object), or
            changes to the world's (an :class:`~torch_gpioius.models.overrides.EstimatorOverrides`, e.g.
            ``EstimatorOverrides(labels={"ray_smoothing": None})``); None: the world's.
        max_steps: cap on planning steps.
        max_travel: fingertip travel budget since the first contact [m] (adds or replaces a ``TravelBudget``).
        stop: stop rules replacing the world's.
        penalty: C(x) replacing the world's.
        metrics_every: ground-truth metrics every k steps (and always at the last), or "schedule": only at 10, 25 and
            50 % of the travel budget, at a stop and at the end (a long run measured at every step spent a third
            of its time measuring).
        metrics_resolution: grid of the metrics [m] (default: the world's).
        interval_every: compute the profile-likelihood interval of the task correlation every k steps
            (visual-tactile; default: never, it costs a few fits).
        regions: visual-tactile with a similarity per region of the outer shape (:class:`torch_gpioius.LocalGPIOIS`
            with this many regions) instead of one (GPIOIS).
        stall: the no-progress rule and its recovery (default :class:`~torch_gpioius.exploration.recovery.NoProgress`:
            no step in 8 took the fingertip 1 cm from where it is: lift along the measured normal and re-approach;
            after 3 such recoveries the run ends as "stalled"); None switches it off.
        outer_tol: visual-tactile with ``GPIOIS(outer_tol=...)``: a truncated basis of the outer kernel matrix that
            drops a positive semi-definite part of trace at most ``outer_tol * sigma^2``, for thousands of camera
            points (fine voxels); each record's ``truncation`` says how far the Gram matrix moved (None: exact).
        device: where the model's data and exact arithmetic live ("cuda" for a GPU, float64 either way; default:
            the CPU). The world, the robot and every record stay on the CPU; a run may resume on another device.
        recorders: :class:`~torch_gpioius.exploration.protocols.Recorder` objects observing the run (after the
            metrics and the interval, before the log).
        progress: report progress (a bar on a terminal, plain lines otherwise).
        log: write a crash-safe exploration log here (docs/data-format.md): one record per completed step, durable
            (fsync) before the next step begins.
        resume_from: continue the run logged in this file from its last complete step (same world, parameters
            and hardware state; appends to the log). The resumed run ends where an uninterrupted one would.
        overwrite: replace an existing file at ``log`` (default: refuse it, since ``resume_from`` relies on it).
        **deprecated: ``theta``, ``kernel``, ``noise``, ``policy``, ``learn``, ``restart_every`` (one release; give
            ``settings=EstimatorOverrides(...)``; ``theta`` is the inverse multiquadric's length, ``kernel=
            InverseMultiquadricKernel(lengthscale=...)``).

    Returns:
        :class:`~torch_gpioius.exploration.trace.Trace`.

    Raises:
        TypeError: ``world`` is not a World, or a keyword ``explore`` does not take.
        ValueError: an invalid argument (names it), a ``log`` that is a folder or lies in a folder that does not
            exist, or a log that does not match this run on resume.
        FileExistsError: ``log`` exists and ``overwrite`` is False (names the file and both ways on).
        FileNotFoundError: ``resume_from`` does not exist.
    """
    if not isinstance(world, World):
        raise TypeError(f"world: expected a torch_gpioius World (Scene2D, Scene3D, MujocoScene, RobotWorld), got "
                        f"{type(world).__name__}")
    loose = loose_keywords("explore", deprecated, LOOSE)
    warn_loose("explore", 2, kernel=loose["kernel"], noise=loose["noise"], policy=loose["policy"],
               learn=loose["learn"], restart_every=loose["restart_every"])
    # the paper's name, a deprecated alias, read here so that its warning and errors name explore
    loose["kernel"] = kernel_for_theta(loose.pop("theta"), loose["kernel"], "explore")
    with warnings.catch_warnings():
        # said once above, naming explore; from_world reads the same keywords and would say it again
        warnings.filterwarnings("ignore", r"ExploreConfig\.from_world\(", DeprecationWarning)
        config = ExploreConfig.from_world(
            world, mode, evidence=evidence, touch=touch, step=step, max_steps=max_steps, max_travel=max_travel,
            stop=stop, penalty=penalty, metrics_every=metrics_every, metrics_resolution=metrics_resolution,
            interval_every=interval_every, regions=regions, stall=stall, outer_tol=outer_tol, device=device,
            settings=settings, **loose)
    if resume_from is not None and log is not None and os.path.abspath(log) != os.path.abspath(resume_from):
        raise ValueError("resume_from appends to its own log; pass log=None or the same path")
    if log is not None:
        _check_log_path(log, "log", must_exist=False, overwrite=overwrite or resume_from is not None)
    if resume_from is not None:
        _check_log_path(resume_from, "resume_from", must_exist=True)
    observers = list(recorders)
    state = hardware = None
    if resume_from is not None:
        hardware = world.hardware()
        state = restore_run(resume_from, world, hardware, config)
        observers.append(LogRecorder(resume_from))
    elif log is not None:
        observers.append(LogRecorder(log))
    return run(world, config, recorders=observers, progress=progress, state=state, hardware=hardware)


def _check_log_path(path, name: str, *, must_exist: bool, overwrite: bool = False) -> None:
    """Refuse a log path before the run starts, naming the argument (nothing is written or truncated here)."""
    if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
        raise ValueError(f"{name}: expected a file path, got {path!r}")
    p = os.fspath(path)
    if os.path.isdir(p):
        raise ValueError(f"{name}: {p} is a folder; give a file in it, e.g. {os.path.join(p, 'run.gpioius')}")
    if must_exist:
        if not os.path.isfile(p):
            raise FileNotFoundError(f"{name}: {p} does not exist (the log of the run to continue)")
        return
    folder = os.path.dirname(p) or "."
    if not os.path.isdir(folder):
        raise ValueError(f"{name}: the folder {folder} of {p} does not exist; create it first")
    if os.path.lexists(p) and not overwrite:
        raise FileExistsError(f"{name}: {p} exists ({os.path.getsize(p)} bytes, a run's log that resume_from relies "
                              f"on); pass resume_from={p!r} to continue it, overwrite=True to replace it, or another "
                              "log path")

