"""The force-field world (``forcefield``) of the paper's robot experiment (Sec. VI) in 3-D: a rigid inner mesh under a
soft outer mesh whose force on the fingertip is a static field, a depth camera that sees the outer one, and an
exploration range for the fingertip (eq. 25).

The hardware is a kinematic UR5 (``kinematics.SimulatedUR5``) behind its safety gate, a simulated fingertip force
sensor over a force-field contact model (the inner object 1000 N/m, the cover a static force field of a few N/m that
the fingertip passes through), a simulated depth camera, and the
:class:`torch_gpioius.exploration.contact.ContactController`.
The cover does not move: for cloth that the fingertip pushes aside, see the MuJoCo world.

Frames: everything is in the UR5 base frame [m] (z up); the objects stand in front of the robot.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

import torch

from ..models.estimator import (COVER_GAP_LIMIT, GAP_FIELD_LABELS, GAP_LABELS, INSIDE_DEPTH,  # noqa: F401
                                EstimatorSettings)
from ..exploration.registry import SceneSupport, register_world
from ..exploration.world import (ContactTruth, ExplorationDefaults, Hardware, Measurement, geometry_hash,
                                 perturbed_approaches)
from ..geometry.metrics import hausdorff_distance
from ..exploration.planning import RangePenalty
from ..sensors.simulated.camera import CameraError, SimulatedDepthCamera, error_key, view_errors
from ..sensors.pointcloud import PinholeCamera, look_at
from ..sensors.simulated import ForceFieldContact
from ..geometry.surfaces import surface_samples
from ..core.validation import as_bounds
from .presets import (DEFAULT_VIEWS, ESTIMATOR_KEYS, INSIDE_SETTINGS, ROBOT_STUDY_DEFAULTS, SETTINGS,  # noqa: F401
                      VIEWS, as_views, estimator_changes, gap_defaults, gap_field_defaults, inside_labels,
                      object_defaults, settings_for, with_inside_depths)
from .ranged import RangedScene
from .ruler import METRICS_EDGE, METRICS_GRID, U_CELL, estimate_metrics_3d, score_surface  # noqa: F401
from .shapes3d import MeshSDF, capsule, mesh_from_sdf, offset, rounded_box, smooth_union

__all__ = ["Scene3D", "paper_objects_3d", "sphere_scene", "simulated_ur5", "estimate_metrics_3d", "score_surface",
           "METRICS_GRID", "METRICS_EDGE",
           "ROBOT_STUDY_DEFAULTS", "COVER_KINDS", "cover_around", "approach_from_above", "first_passage", "place"]

#: The inward search of a slide that lost contact (``ContactConfig.max_normal_travel``) as a fraction of the seen
#: body's largest extent, and its bounds [m]: see :func:`lost_contact_search`.
LOST_CONTACT_SEARCH = (0.1, 0.01, 0.05)


def lost_contact_search(outer: trimesh.Trimesh) -> float:
    """How far [m] the simulated fingertip presses inward along the contact normal before a slide counts as having
    lost contact (``ContactConfig.max_normal_travel``): a tenth of the cover's largest extent (what the camera sees,
    not the hidden body), 1-5 cm, rounded to 0.1 mm. A torso keeps the controller's 5 cm; a 15 cm body searches
    1.7 cm.

    A slide that runs off an edge or a thin part presses along the old normal, past the surface it left, and finds
    nothing however far it goes; the re-approach that follows (``exploration.loop.recover``, along the estimate's
    inward normal) finds the surface again, at a median 9 mm. On the object sets' blobs the 5 cm searches took 39 %
    of a 0.6 m budget (steps that lost contact, 40 runs of objects 0-39), and three flat blobs (52, 104 and, with
    the other settings of their time, 60 and 73) spent their travel on them and ended without an estimate
    (docs/results-benchmark.md "Every object reached?").
    """
    fraction, lo, hi = LOST_CONTACT_SEARCH
    return round(float(np.clip(fraction * float(np.max(outer.extents)), lo, hi)), 4)


def simulated_ur5(start, direction, lower, upper, *, tool_length: float = 0.05,
                  q_home=(0.0, -1.2, 1.5, -1.9, -1.57, 0.0), margin: float = 0.1, floor: float | None = None):
    """A kinematic UR5 placed by IK with its fingertip at ``start`` pointing along ``direction``, behind a gate
    whose workspace box is the exploration range [``lower``, ``upper``] and the start, grown by ``margin`` [m];
    with a support plane at height ``floor`` [m] the box ends 5 mm below it (the controller keeps the fingertip
    above it, the gate refuses what would pass it)."""
    from kinematics import UR5, SafetyGate, SimulatedUR5, tool_rotation

    ur5 = UR5(tool_offset=(0.0, 0.0, tool_length))
    T = torch.eye(4, dtype=torch.float64)
    T[:3, :3] = tool_rotation(direction)
    T[:3, 3] = torch.as_tensor(start, dtype=torch.float64)
    q0 = ur5.inverse_kinematics(T, q_init=torch.as_tensor(q_home, dtype=torch.float64))
    lo = np.minimum(lower, start) - margin
    hi = np.maximum(upper, start) + margin
    if floor is not None:
        lo[2] = max(lo[2], floor - 0.005)
    return SimulatedUR5(ur5, q0, SafetyGate(ur5, lo.tolist(), hi.tolist()))


def _mesh(m, name: str) -> trimesh.Trimesh:
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise ValueError(f"{name}: expected a non-empty trimesh.Trimesh [m]")
    if not np.isfinite(m.vertices).all():
        raise ValueError(f"{name}: vertices contain NaN or inf")
    if not m.is_watertight:
        raise ValueError(f"{name}: the mesh must be closed (watertight)")
    return m


class Scene3D(RangedScene):
    """A covered object in 3-D, seen by a depth camera and touched by the UR5's fingertip (the force-field world,
    registered as ``forcefield``).

    Why this many parameters: the body, the cover, the approach and range, and the simulated sensors are each one
    fact of the scene; :meth:`from_mesh` builds most of them from a mesh.

    Args:
        inner: closed mesh of the rigid inner object [m], base frame.
        outer: closed mesh of the cover's outer surface [m] (must contain the inner one).
        start: `(3,)` fingertip start position [m], outside the outer mesh.
        direction: `(3,)` approach direction (normalised here); the tool points along it.
        bounds: `(2, 3)` exploration range `[min corner; max corner]` [m] (trimesh's ``mesh.bounds`` layout): the
            range penalty C (eq. 25) keeps the planner inside it, and the metrics are evaluated inside it.
        name: label for figures and records.
        camera: point-cloud source seeing the outer mesh (default: :meth:`cameras` of ``views``).
        cover_stiffness: stiffness of the cover in the simulated force model [N/m].
        sensor_noise: force-sensor noise per axis [N] (the OptoForce OMD-20 is specified to about 0.01-0.03 N).
        seed: seed of the sensor and camera noise.
        defaults: overrides of :data:`ROBOT_STUDY_DEFAULTS`.
        support: the support plane the object stands on: "base" (default: a table at the inner mesh's lowest
            point), a height z [m], or None (no table: the fingertip may pass under the object). Nothing passes
            the plane: the contact controller keeps the fingertip above it and the robot's gate refuses what would
            go more than 5 mm below.
        views: the simulated camera's views of the cover when no ``camera`` is given (:data:`VIEWS`): a tuple of
            names, their number (1: the paper's fixed camera; 2: and its mirror; 3: and the wrist view), or "paper"
            (the fixed camera alone).

    Raises:
        ValueError: open or invalid meshes, an outer mesh not containing the inner one, a start inside the outer
            mesh, an approach ray missing the inner mesh, invalid bounds, or unknown views.
    """

    def __init__(self, inner: trimesh.Trimesh, outer: trimesh.Trimesh, start, direction, bounds, name: str = "",
                 camera=None, cover_stiffness: float = 5.0, sensor_noise: float = 0.02, seed: int = 0,
                 defaults: ExplorationDefaults | None = None, support: float | str | None = "base",
                 views=DEFAULT_VIEWS, camera_error=None) -> None:
        self.inner, self.outer = _mesh(inner, "inner"), _mesh(outer, "outer")
        self.views = as_views(views)
        if camera_error is not None and camera is not None:
            raise ValueError("camera_error: this scene has a camera of its own; simulate its error in that camera "
                             "(SimulatedDepthCamera(error=))")
        self.camera_error = CameraError.parse(camera_error if camera_error is not None else CameraError())
        base = float(self.inner.bounds[0, 2])
        if support == "base":
            self.support: float | None = base
        elif support is None:
            self.support = None
        elif isinstance(support, bool) or not isinstance(support, (int, float)) or not math.isfinite(support) \
                or support > base + 1e-9:
            raise ValueError(f"support: must be 'base', None or a height [m] at or below the body's lowest point "
                             f"({base:.4f} m), got {support!r}")
        else:
            self.support = float(support)
        self.inner_sdf, self.outer_sdf = MeshSDF(self.inner), MeshSDF(self.outer)
        # containment on at most 2000 inner vertices (trimesh's ray-based contains needs GBs for large meshes)
        probe = self.inner.vertices[::max(1, len(self.inner.vertices) // 2000)]
        if not bool((self.outer_sdf(probe)[0] <= 1e-9).all()):
            raise ValueError("outer: must contain the inner mesh (a cover around the object)")
        self.start = np.asarray(start, dtype=np.float64).reshape(-1)
        d = np.asarray(direction, dtype=np.float64).reshape(-1)
        if self.start.shape != (3,) or not np.isfinite(self.start).all():
            raise ValueError(f"start: expected a finite (3,) position [m], got {start!r}")
        if d.shape != (3,) or not np.isfinite(d).all() or np.linalg.norm(d) == 0:
            raise ValueError("direction: must be a finite non-zero 3-vector")
        self.direction = d / np.linalg.norm(d)
        self.range = as_bounds(bounds, 3)
        if float(self.outer_sdf(self.start[None])[0][0]) <= 0:
            raise ValueError("start: must lie outside the outer mesh")
        if not cover_stiffness >= 0:
            raise ValueError("cover_stiffness must be >= 0 [N/m]")
        self.name = name
        self._inner_samples: dict[float, np.ndarray] = {}
        self.cover_stiffness = float(cover_stiffness)
        if isinstance(sensor_noise, bool) or not (isinstance(sensor_noise, (int, float)) and
                                                  math.isfinite(sensor_noise) and 0 <= sensor_noise <= 1.0):
            raise ValueError(f"sensor_noise: must be in [0, 1] N, got {sensor_noise!r}")
        self.sensor_noise, self.seed = float(sensor_noise), int(seed)
        self._camera = camera
        self._given_camera = camera         # a user's source (perturbed reseeds it); _camera also caches the default
        # the fixed and mirrored views stand on tripods placed for this approach; a seeded perturbation of the approach
        # does not move them (perturbed carries it over), only the wrist view follows the arm
        self._tripod_direction = self.direction
        self._defaults = defaults or ROBOT_STUDY_DEFAULTS
        self.first_contact()  # raises if the approach misses

    dim = 3

    @classmethod
    def from_mesh(
        cls,
        inner,
        cover: str = "tight",
        *,
        start=None,
        direction=None,
        bounds=None,
        pose=None,
        at=None,
        scale: float = 1.0,
        repair: bool = True,
        gap: float | None = None,
        bridge: float = 0.03,
        resolution: float | None = None,
        gap_far: float = 0.05,
        thick_side=(0.0, 1.0, 0.0),
        name: str = "",
        seed: int = 0,
        cover_stiffness: float | None = None,
        sensor_noise: float = 0.02,
        defaults: ExplorationDefaults | None = None,
        support: float | str | None = "base",
        settings: str = "default",
        views=None,
        estimator=None,
        camera_error=None,
        **deprecated,
    ) -> "Scene3D":
        """A force-field scene around any closed mesh: a user's scan or CAD model as the hidden body.

        The mesh is loaded, checked and repaired if need be (:func:`torch_gpioius.sim.meshes.load_mesh`, which warns
        with the repair's size); the cover is built from the mesh's exact signed distance
        (:func:`cover_around`). Without ``start``, ``direction`` and ``bounds`` the robot comes from above
        (:func:`approach_from_above`).

        Args:
            inner: a ``trimesh.Trimesh`` or a path (STL, OBJ, PLY, GLB, OFF) [m after ``scale``].
            cover: "tight" (the body grown by ``gap``), "loose" (grown, and bridged over concavities narrower than
                2 ``bridge``, as a draped cloth), "uneven" (``gap`` on one side, ``gap_far`` on the ``thick_side``)
                or "hanging" (loose on top, hanging straight down to the table); :func:`cover_around`.
            start: `(3,)` fingertip start [m] (default: :func:`approach_from_above`).
            direction: `(3,)` approach direction (default: down).
            bounds: `(2, 3)` exploration range `[min corner; max corner]` [m] (default: :func:`approach_from_above`).
            pose: where the object stands (`(4, 4)` or ``{"position", "quat" | "rpy_deg"}``), after ``scale``.
            at: `(3,)` where the bottom centre of the (posed) object's bounding box goes [m], or None.
            scale: factor to metres (0.001 for millimetres).
            repair: repair an open mesh (False refuses it).
            gap: the cover's distance from the body [m] (default 8 mm tight, 1 cm loose, 5 mm uneven (its thin
                side) and hanging (on top)).
            bridge: the loose and hanging covers' bridging radius [m].
            resolution: the cover's grid spacing [m] (default: 1/80 of the largest extent, 2-6 mm).
            gap_far: the uneven cover's gap on its thick side [m].
            thick_side: `(3,)` the uneven cover's thick side, a horizontal direction (default +y).
            name: label.
            seed: seed of the sensor and camera noise.
            sensor_noise: force-sensor noise per axis [N].
            defaults: overrides of :data:`ROBOT_STUDY_DEFAULTS`.
            cover_stiffness: [N/m] (default 5 tight, 3 for the others, as objects E-H).
            support: the table under the object ("base": at its lowest point; a height [m]; None: none).
            settings: "default" (:func:`object_defaults` and all three :data:`VIEWS`) or "paper" (the robot study's
                :data:`ROBOT_STUDY_DEFAULTS` and the paper's single fixed camera); ``defaults`` replaces either.
            views: the camera's views (see the class; default: by ``settings``).
            estimator: changes to the estimator's settings of ``settings`` (an
                :class:`~torch_gpioius.models.overrides.EstimatorOverrides` or its plain dict, e.g.
                ``EstimatorOverrides(kernel="imq", noise=0.05, labels={"touch_inside": None})``;
                docs/reference/settings.md); None: the preset's.
            camera_error: the simulated cameras' errors (:meth:`with_camera_error`: ``"6mm,1deg"``, ``"3x,20%holes"``);
                default: none.
            **deprecated: the estimator's loose settings of earlier releases, for one release: ``kernel``,
                ``noise``, ``voxel``, ``learn`` and the inside points' ``touch_inside``, ``vision_inside``,
                ``vision_inside_gap`` (0: none), ``cover_offset``; give ``estimator=EstimatorOverrides(...)``
                (:func:`estimator_changes` says how each maps).

        Why this many parameters: the body, its cover and the approach are each a few numbers a user's object needs
        (the estimator's settings, the part that grows, are one object, ``estimator``).

        Raises:
            ValueError: an unreadable, empty or irreparable mesh, an unknown cover, a start inside the cover or an
                approach that misses the body (each names the problem).
            TypeError: a keyword it does not take.
        """
        from ..models.overrides import loose_keywords, warn_loose
        from .meshes import load_mesh

        loose = {k: v for k, v in loose_keywords("Scene3D.from_mesh", deprecated, ESTIMATOR_KEYS).items()
                 if v is not None}
        warn_loose("Scene3D.from_mesh", 2, **loose)

        if cover not in COVER_KINDS:
            raise ValueError(f"cover: the force-field world has the covers {COVER_KINDS}, got {cover!r}")
        if settings not in SETTINGS:
            raise ValueError(f"settings: must be one of {SETTINGS}, got {settings!r}")
        mesh = place(load_mesh(inner, scale=scale, pose=pose, repair=repair, name="inner"), at)
        chosen = settings_for(settings, mesh)
        views = as_views(chosen["views"] if views is None else views)
        defaults = chosen["defaults"] if defaults is None else defaults
        changes = estimator_changes(estimator, **loose)            # by the one resolver
        if changes:
            defaults = defaults.with_estimator(changes.apply(defaults.estimator))
        gap = {"tight": 0.008, "loose": 0.01}.get(cover, 0.005) if gap is None else gap
        outer = cover_around(mesh, cover, gap=gap, bridge=bridge, resolution=resolution, gap_far=gap_far,
                             thick_side=thick_side)
        if start is None or direction is None or bounds is None:
            s, d, b = approach_from_above(mesh, outer)
            start, direction = (s, d) if start is None and direction is None else (start, direction)
            if start is None or direction is None:
                raise ValueError("start, direction: give both or neither")
            bounds = b if bounds is None else bounds
        stiffness = (5.0 if cover == "tight" else 3.0) if cover_stiffness is None else cover_stiffness
        return cls(mesh, outer, start, direction, bounds, name=name, cover_stiffness=stiffness,
                   sensor_noise=sensor_noise, seed=seed, defaults=defaults, support=support, views=views,
                   camera_error=camera_error)

    # ------------------------------------------------------------------ the World interface
    @property
    def defaults(self) -> ExplorationDefaults:
        return self._defaults

    @property
    def camera(self):
        """The point-cloud source (default: :meth:`cameras` of :attr:`views`)."""
        if self._camera is None:
            self._camera = self.cameras(self.views)
        return self._camera

    def cameras(self, views=("fixed",)):
        """The simulated depth cameras of ``views`` (:data:`VIEWS`; names, a count or "paper"): the fixed camera
        alone is :meth:`default_camera`; several views are one :class:`~torch_gpioius.sensors.MultiViewSource` whose
        view k draws its noise from ``[seed, k]``.

        - "fixed": the paper's camera (:meth:`default_camera`), behind the approach, 30 cm to one side, 30 cm up.
        - "mirrored": the same camera mirrored to the other side of the approach (a second tripod, or the first one
          moved once), so that the far side of the body is seen too.
        - "wrist": a short-range depth camera on the arm's wrist (:meth:`PinholeCamera.realsense_d405`), 35 cm back
          from the first contact along the approach, captured before the first touch.
        """
        views = as_views(views)
        if views == ("fixed",):
            return self.default_camera()
        from ..sensors.pointcloud import MultiViewSource

        make = {"fixed": lambda k: self.default_camera(seed=[self.seed, k]),
                "mirrored": lambda k: self.default_camera(seed=[self.seed, k], side=-1.0),
                "wrist": lambda k: self.wrist_camera(seed=[self.seed, k])}
        return MultiViewSource([make[v](k) for k, v in enumerate(views)], views)

    def wrist_camera(self, distance: float = 0.35, seed=0) -> SimulatedDepthCamera:
        """A wrist-mounted short-range depth camera (:meth:`PinholeCamera.realsense_d405`; depth noise 0.5 mm +
        2 mm/m^2 * z^2) at ``distance`` [m] back from the first contact along the approach, looking along it (an
        approach that misses the body: from the point of its line nearest the range's centre)."""
        try:
            target = self.first_contact()
        except ValueError:          # an approach that misses (the run will say so): aim along it at the range's middle
            target = self.start + self.direction * float((self.range.mean(axis=0) - self.start) @ self.direction)
        eye = target - distance * self.direction
        up = (0.0, 0.0, 1.0) if abs(self.direction[2]) < 0.9 else (1.0, 0.0, 0.0)
        return SimulatedDepthCamera(self.outer, PinholeCamera.realsense_d405(0.25), look_at(eye, target, up),
                                    noise_a=0.0005, noise_b=0.002, seed=seed, error=self.camera_error,
                                    error_key=self._error_key(), support=self.support)

    def hardware(self) -> Hardware:
        from ..exploration.contact import ContactConfig, ContactController
        from ..sensors.simulated import SimulatedForceSensor

        robot = simulated_ur5(self.start, self.direction, self.range[0], self.range[1], floor=self.support)
        field = self.contact_model()
        sensor = SimulatedForceSensor(field, robot.read_pose, clock=lambda: robot.time,
                                      noise_std=self.sensor_noise, seed=self.seed)
        # the default views are built afresh for each hardware, as the robot and the sensor are, so that their noise
        # starts from the seed every time: one camera shared by every run of a scene carried its noise generator's
        # state from one run to the next, and the same call gave another cloud in the same process (a study worker's
        # second run of a seed-0 scene, a test run after another); a given source is the user's and used as it is
        camera = self._given_camera if self._given_camera is not None else self.cameras(self.views)
        config = ContactConfig(floor=self.support, max_normal_travel=lost_contact_search(self.outer))
        return Hardware(robot, sensor, camera, ContactController(robot, sensor, config), self.tactile_pad(robot, field))

    def tactile_pad(self, robot, field=None):
        """A DIGIT-like gel pad at the fingertip (:class:`~torch_gpioius.sensors.simulated.gelpad.SimulatedGelPad`): it
        faces the contact force of the field, sees the body through 0.5 mm of pinched cloth."""
        from ..sensors.simulated.gelpad import SimulatedGelPad

        field = field or self.contact_model()
        return SimulatedGelPad(self.inner_sdf.distance, lambda: robot.tool_position().detach().numpy(),
                               lambda: field(robot.tool_position().detach()).numpy(), clock=lambda: robot.time)

    def penalty(self) -> RangePenalty:
        return self.range_penalty()

    def crop_box(self) -> np.ndarray:
        return self.range

    def measure(self, model, contacts, resolution: float | None = None) -> Measurement:
        return estimate_metrics_3d(model, self, METRICS_GRID if resolution is None else resolution, contacts=contacts)

    def fingerprint(self) -> str:
        return geometry_hash(self.inner.vertices, self.inner.faces, self.outer.vertices, self.outer.faces,
                             self.start, self.direction, self.range,
                             [self.cover_stiffness, self.sensor_noise, self.seed,
                              math.nan if self.support is None else self.support],
                             # the paper's single view hashes as before views existed (its logs still resume)
                             *([] if self.views == ("fixed",) else [[VIEWS.index(v) for v in self.views]]),
                             # a scene without a camera error hashes as before there were any
                             *self.camera_error.fingerprint())

    def snapshot(self, hw: Hardware) -> dict[str, np.ndarray]:
        return {"joints": hw.robot.read_joints().numpy(), "clock": np.array([hw.robot.time]),
                **{f"sensor_{k}": v for k, v in hw.sensor.get_state().items()}}

    def restore(self, hw: Hardware, state: dict[str, np.ndarray]) -> None:
        hw.robot.set_state(torch.as_tensor(state["joints"]), float(np.asarray(state["clock"]).reshape(-1)[0]))
        hw.sensor.set_state({k[len("sensor_"):]: v for k, v in state.items() if k.startswith("sensor_")})

    def with_settings(self, settings: str) -> "Scene3D":
        """The same objects, approach and range under other exploration settings: "default" (:func:`object_defaults`
        of the inner mesh, all three :data:`VIEWS`) or "paper" (:data:`ROBOT_STUDY_DEFAULTS`, the fixed camera
        alone). The built-in objects E-H are made with the paper's; this gives them a user's defaults.

        Raises:
            ValueError: an unknown setting, or a scene with a camera of its own (its views are the user's).
        """
        chosen = settings_for(settings, self.inner)
        if self._given_camera is not None:
            raise ValueError("settings: this scene has a camera of its own; its views are not the settings' to change")
        return self._copy(**chosen)

    def with_estimator(self, estimator) -> "Scene3D":
        """The same scene with other estimator settings: an :class:`~torch_gpioius.models.estimator.EstimatorSettings`
        in place of its own, or an :class:`~torch_gpioius.models.overrides.EstimatorOverrides` (or its plain dict: a
        scene file's ``[estimator]`` section) applied to its own.

        Raises:
            ValueError: anything else, or changes that do not hold together (named).
        """
        from ..models.overrides import resolved

        return self._copy(defaults=self.defaults.with_estimator(resolved(estimator, self.defaults.estimator)))

    def with_views(self, views) -> "Scene3D":
        """The same objects, approach, range and settings seen by other simulated views (:func:`as_views`: names
        from :data:`VIEWS`, a count or "paper"); the tripods stand where they stood.

        Raises:
            ValueError: unknown views, or a scene with a camera of its own (its views are the user's).
        """
        views = as_views(views)
        if self._given_camera is not None:
            raise ValueError("views: this scene has a camera of its own; its views are not the simulated ones")
        return self._copy(views=views)

    def with_camera_error(self, error) -> "Scene3D":
        """The same scene seen by simulated cameras whose calibration is off: each view of each run (its seed) draws a
        rigid error of the sizes ``error`` gives (a :class:`~torch_gpioius.sensors.simulated.CameraError` or its
        text, ``"6mm,1deg"``; ``"0"``: none) and moves its captures by it (:meth:`camera_errors` says what each view
        applies); the error's sensing terms (``"3x"``, ``"20%"``, ``"20%holes"``) scale every view's depth noise and
        lose its pixels.

        Raises:
            ValueError: a malformed error, or a scene with a camera of its own (simulate the error in that camera).
        """
        error = CameraError.parse(error)
        if self._given_camera is not None:
            raise ValueError("camera_error: this scene has a camera of its own; simulate its error in that camera "
                             "(SimulatedDepthCamera(error=))")
        return self._copy(camera_error=error)

    def _error_key(self) -> tuple:
        return error_key(self.name)

    def camera_errors(self) -> dict[str, dict]:
        """The extrinsic error each simulated view of this scene (its seed) applies, by view name
        (:meth:`~torch_gpioius.sensors.simulated.AppliedCameraError.as_record`); empty without one (drawn as the
        cameras draw it, without building them)."""
        return view_errors(self.camera_error, self.views, self.seed, self._error_key())

    def perturbed(self, seed: int) -> "Scene3D":
        """The same objects with a seeded perturbation (seed 0: unchanged): the start moved uniformly within a
        2 cm disc across the approach, the approach direction turned by up to 10 deg (uniform on the cap), and the
        force-sensor and camera noise drawn from ``seed``. A perturbed approach must still hit the object."""
        if seed == 0:
            return self
        for start, direction in perturbed_approaches(self.start, self.direction, np.random.default_rng([seed, 3])):
            # a given camera keeps its poses and draws its noise from the seed (PointCloudSource.reseeded); the
            # default views are rebuilt with the seed's noise: the tripods where they stood, the wrist on the new
            # approach
            camera = None if self._given_camera is None else self._given_camera.reseeded(seed)
            try:
                return self._copy(start=start, direction=direction, seed=seed, camera=camera)
            except ValueError:
                continue
        raise ValueError(f"seed {seed}: no perturbed approach hits the object")

    def _copy(self, **changes) -> "Scene3D":
        """This scene with ``changes`` to its constructor's arguments; the tripods stand where they stood (a copy's
        views are placed for this scene's unperturbed approach, not its own)."""
        kw = dict(start=self.start, direction=self.direction, bounds=self.range, name=self.name,
                  camera=self._given_camera, cover_stiffness=self.cover_stiffness, sensor_noise=self.sensor_noise,
                  seed=self.seed, defaults=self._defaults, support=self.support, views=self.views,
                  camera_error=self.camera_error if self._given_camera is None else None)
        scene = Scene3D(self.inner, self.outer, **{**kw, **changes})
        scene._tripod_direction = self._tripod_direction
        return scene

    # ------------------------------------------------------------------ geometry
    #: An approach must pass at least this deep [m] into the inner mesh: one that only grazes an edge meets less
    #: than the contact threshold's force (1 N at 1000 N/m is 1 mm) and passes through the body.
    MIN_APPROACH_DEPTH = 0.003

    def first_contact(self) -> np.ndarray:
        """`(3,)` first point of the inner mesh hit from ``start`` along ``direction`` [m].

        Raises:
            ValueError: the approach ray misses the inner mesh, or only grazes it (its first passage through the body
                is never :attr:`MIN_APPROACH_DEPTH` deep).
        """
        passage = first_passage(self.inner, self.true_distance, self.start, self.direction)
        if passage is None:
            raise ValueError("direction: the approach ray from start misses the inner mesh")
        t, depth = passage
        if depth < self.MIN_APPROACH_DEPTH:
            raise ValueError(f"direction: the approach ray only grazes the inner mesh ({depth * 1e3:.1f} mm deep "
                             f"at most; at least {self.MIN_APPROACH_DEPTH * 1e3:.0f} mm is needed to feel it)")
        return self.start + t * self.direction

    def true_surface_samples(self, spacing: float) -> np.ndarray:
        """`(n, 3)` samples of the whole inner mesh, about one per ``spacing``^2 [m]."""
        return surface_samples(self.inner, spacing)

    def inner_outer_hausdorff(self, spacing: float = 0.003) -> float:
        """Hausdorff distance between the inner and outer surfaces [m] (the whole meshes).

        Both surfaces are sampled every ``spacing`` (vertices plus area-uniform samples) and compared with k-d
        trees: within about ``spacing`` of the exact value, seconds instead of minutes for 10^5 faces.
        """
        return hausdorff_distance(surface_samples(self.inner, spacing), surface_samples(self.outer, spacing))

    def contact_model(self, k_inner: float = 1000.0) -> ForceFieldContact:
        """Force on a point fingertip: the rigid inner mesh and the soft cover (``cover_stiffness``)."""
        return ForceFieldContact(self.inner_sdf, self.outer_sdf, k_inner=k_inner, k_cover=self.cover_stiffness,
                                 inner_bounds=self.inner.bounds, outer_bounds=self.outer.bounds)

    def default_camera(self, scale: float = 0.5, seed=None, side: float = 1.0) -> SimulatedDepthCamera:
        """A Kinect v2 (half resolution; depth noise 1.5 mm + 1.5 mm/m^2 * z^2) looking at the centre of the
        exploration range from 1.1 m, from behind the approach (the unperturbed one of a seeded scene: a tripod does not
        move with the arm; so that it sees what the robot will touch),
        30 cm to the side (``side`` -1: the other side) and 30 cm up; noise from ``seed`` (default: the scene's)."""
        target = self.range.mean(axis=0)
        back = -self._tripod_direction                # the unperturbed approach's (see __init__)
        lateral = np.cross(back, [0.0, 0.0, 1.0]) if abs(back[2]) < 0.9 else np.array([0.0, -1.0, 0.0])
        eye = target + back + 0.3 * side * lateral / np.linalg.norm(lateral) + np.array([0.0, 0.0, 0.3])
        eye = target + 1.1 * (eye - target) / np.linalg.norm(eye - target)
        return SimulatedDepthCamera(self.outer, PinholeCamera.kinect_v2(scale), look_at(eye, target),
                                    noise_a=0.0015, noise_b=0.0015, seed=self.seed if seed is None else seed,
                                    error=self.camera_error, error_key=self._error_key(), support=self.support)

    def true_distance(self, points: np.ndarray) -> np.ndarray:
        """`(n,)` exact signed distance of `(n, 3)` points from the inner mesh [m] (negative inside)."""
        return self.inner_sdf.distance(np.asarray(points, dtype=np.float64).reshape(-1, 3))

    def contact_truth(self, hw, contact):
        """The contact's distance from the inner mesh, and whether the fingertip presses into the body itself (the
        body's stiff field acts only inside it; the cover's weak field acts everywhere inside the cover)."""
        tip = hw.robot.tool_position().detach().numpy()
        return ContactTruth(float(self.true_distance(np.asarray(contact)[None])[0]),
                            bool(self.true_distance(tip[None])[0] < 0.0))

    def truth(self) -> dict:
        """The true inner and outer meshes [m]."""
        return {"inner": self.inner, "outer": self.outer}

    def __repr__(self) -> str:
        return (f"Scene3D({self.name!r}, inner volume={self.inner.volume * 1e6:.0f} cm^3, "
                f"outer volume={self.outer.volume * 1e6:.0f} cm^3)")


def place(mesh: trimesh.Trimesh, at=None) -> trimesh.Trimesh:
    """``mesh`` moved so that the bottom centre of its bounding box is at ``at`` `(3,)` [m] (None: unchanged)."""
    if at is None:
        return mesh
    a = np.asarray(at, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.isfinite(a).all():
        raise ValueError(f"at: expected a finite (3,) position [m], got {at!r}")
    lo, hi = mesh.bounds
    out = mesh.copy()
    out.apply_translation(a - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]]))
    return out


#: The force-field world's cover kinds (:func:`cover_around`).
COVER_KINDS = ("tight", "loose", "uneven", "hanging")


def cover_around(mesh: trimesh.Trimesh, kind: str = "tight", *, gap: float = 0.008, bridge: float = 0.03,
                 resolution: float | None = None, gap_far: float = 0.05,
                 thick_side=(0.0, 1.0, 0.0)) -> trimesh.Trimesh:
    """The outer surface of a cover over a closed mesh, for the force-field world.

    * "tight": the level set ``{d = gap}`` of the body's exact signed distance ``d`` (a cover of uniform thickness).
    * "loose": the morphological closing of the tight cover by a ball of radius ``bridge``: it spans concavities
      narrower than ``2 bridge`` (between a bunny's ears, under a mug's handle) as a draped cloth does, and keeps
      to the body elsewhere. The dilation is exact (``{d <= gap + bridge}``); the erosion uses the Euclidean distance
      transform of that set on the grid, so the surface is within about one grid spacing of the exact closing.

    Two covers whose gap varies over the body, as real cloth's does (a cover of one gap is what a camera-only surface
    shrunk by one measured gap matches by construction):

    * "uneven" (thick on one side, thin on the other): the level set ``{d = g(x)}`` with a gap ``g`` that grows
      linearly from ``gap`` on the body's extreme opposite ``thick_side`` to ``gap_far`` on its extreme towards it
      (a horizontal direction); on a body narrower than twice that growth, ``g`` grows at a slope of 1/2
      (:data:`UNEVEN_SLOPE`, with a warning) and stops short of ``gap_far``. A slope below 1 keeps the level set one
      closed layer around the body.
    * "hanging" (a cloth laid over the body that hangs straight down to the table): the loose cover, and below
      every part of it the column down to the table (the body's lowest point, less ``gap``). It lies ``gap`` off the
      top and stands off by up to the body's overhang below its widest part (a sphere's lower half, a duck's
      head). The hanging part's surface comes from the Euclidean distance transform of the set on the grid (within
      about one spacing).

    All are meshed by marching cubes on a grid of ``resolution`` (error about that spacing); the result contains
    the tight cover (it is united with ``{d <= gap}`` on the grid).

    Args:
        mesh: closed inner mesh [m].
        kind: one of :data:`COVER_KINDS`: "tight", "loose", "uneven" or "hanging".
        gap: the cover's distance from the body [m] (> 0; the uneven cover's on its thin side).
        bridge: the loose and hanging covers' bridging radius [m] (> 0).
        resolution: grid spacing [m] (default: 1/80 of the largest extent, clipped to 2-6 mm).
        gap_far: the uneven cover's gap on its thick side [m] (>= ``gap``, at most 0.2).
        thick_side: `(3,)` the uneven cover's thick side, a horizontal direction in the base frame (its z is
            dropped; default +y).

    Returns:
        A closed ``trimesh.Trimesh`` [m].

    Raises:
        ValueError: an unknown kind, a non-positive gap, bridge or resolution, a far gap below the near one, or a
            thick side with no horizontal direction.
    """
    if kind not in COVER_KINDS:
        raise ValueError(f"kind: must be one of {COVER_KINDS}, got {kind!r}")
    for label, v in (("gap", gap), ("bridge", bridge), ("gap_far", gap_far)):
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= 0.2):
            raise ValueError(f"{label}: must be in (0, 0.2] m, got {v!r}")
    h = float(np.clip(float(mesh.extents.max()) / 80, 0.002, 0.006)) if resolution is None else float(resolution)
    if not (math.isfinite(h) and 0 < h <= 0.05):
        raise ValueError(f"resolution: must be in (0, 0.05] m, got {resolution!r}")
    thickness = None
    if kind == "uneven":
        thickness = _uneven_gap(mesh, gap, gap_far, thick_side)
    reach = (gap_far if kind == "uneven" else gap) + (2 * bridge if kind in ("loose", "hanging") else 0.0) + 3 * h
    from .meshes import check_grid

    check_grid(mesh.bounds[0] - reach, mesh.bounds[1] + reach + h, h, "resolution", "the cover's grid")
    # a level set that passes exactly through grid nodes (a flat face at a grid plane's distance) gives marching
    # cubes zero-area triangles, and the mesh without them is open: the grid starts at an irrational fraction of a
    # cell, and where the result is still open the cover is meshed again on grids shifted by other fractions
    import warnings

    tries = [(shift, h) for shift in _GRID_SHIFTS] + [(_GRID_SHIFTS[0], h * f) for f in _FINER]
    for attempt, (shift, step) in enumerate(tries):
        out = _cover_on_grid(mesh, kind, gap, bridge, step, mesh.bounds[0] - reach - shift * step,
                             mesh.bounds[1] + reach, thickness)
        if not out.is_watertight and _fill_small_holes(out, step):
            warnings.warn(f"cover_around: the {kind} cover's mesh had a few holes of less than a cell "
                          f"({step * 1e3:.2g} mm); they were filled", RuntimeWarning, stacklevel=2)
        if out.is_watertight:
            if attempt:
                warnings.warn(f"cover_around: the {kind} cover's mesh was open on the first grid; meshed again on a "
                              f"grid of {step * 1e3:.2g} mm shifted by {shift:.3f} of a cell, where it is closed",
                              RuntimeWarning, stacklevel=2)
            return out
    raise ValueError(f"cover_around: the cover mesh is not closed ({kind}, gap {gap} m, grid {h:.4g} m) on "
                     f"{len(_GRID_SHIFTS)} shifted grids and {len(_FINER)} finer ones")


#: Grids finer than the first, as fractions of its spacing, that :func:`cover_around` tries last.
_FINER = (0.8, 0.6)


def _fill_small_holes(out: trimesh.Trimesh, h: float) -> bool:
    """Fill ``out``'s holes when each is a small loop (at most 8 open edges, none longer than two cells): what a few
    degenerate triangles left; True when it is then closed. Larger holes are left open (a real defect)."""
    edges = out.edges_sorted
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    open_edges = unique[counts == 1]
    if len(open_edges) == 0 or (counts > 2).any() or len(open_edges) > 64:
        return False
    if float(np.linalg.norm(np.diff(out.vertices[open_edges], axis=1), axis=-1).max()) > 2 * h:
        return False
    trimesh.repair.fill_holes(out)
    return bool(out.is_watertight)


#: The cover's level below zero, in cells (:func:`_cover_on_grid`): irrational, so that no lattice distance meets it.
_LEVEL_OFFSET = 1e-3 / math.pi

#: Fractions of a cell by which :func:`cover_around` shifts its grid, the first one always (irrational: no flat face
#: of a body placed at round coordinates lies at a node's distance), the others when a grid still gives an open mesh.
_GRID_SHIFTS = (1 / math.pi, 1 / math.e, 1 / math.sqrt(5), 0.5 + 1 / (4 * math.pi))

#: The uneven cover's steepest gap, metres of gap a metre along the thick side (:func:`cover_around`).
UNEVEN_SLOPE = 0.5


def _uneven_gap(mesh: trimesh.Trimesh, gap: float, gap_far: float, thick_side):
    """The uneven cover's gap: `(n, 3)` points [m] -> `(n,)` [m], ``gap`` on the body's extreme opposite
    ``thick_side`` (made horizontal and unit) growing linearly to ``gap_far`` on its extreme towards it."""
    side = np.asarray(thick_side, dtype=float).reshape(-1)
    if side.shape != (3,) or not np.isfinite(side).all() or np.linalg.norm(side[:2]) < 1e-9:
        raise ValueError(f"thick_side: must be a finite 3-vector with a horizontal part, got {thick_side!r}")
    side = np.r_[side[:2] / np.linalg.norm(side[:2]), 0.0]
    if gap_far < gap:
        raise ValueError(f"gap_far: the thick side's gap ({gap_far} m) must be at least the thin side's ({gap} m)")
    along = mesh.vertices @ side
    low, width = float(along.min()), float(np.ptp(along))
    # a gap growing as fast as the distance from the body folds the layer onto itself: on a body narrower than
    # (gap_far - gap) / UNEVEN_SLOPE along the thick side, the gap grows at that slope and stops short of gap_far
    slope = min((gap_far - gap) / width, UNEVEN_SLOPE) if width > 0 else 0.0
    if gap + slope * width < gap_far - 1e-9:
        import warnings

        warnings.warn(f"cover_around: the uneven cover's gap grows at most {UNEVEN_SLOPE:g} m a metre: over the "
                      f"body's {width * 100:.3g} cm along the thick side it reaches {(gap + slope * width) * 100:.3g} "
                      f"cm, not {gap_far * 100:.3g} cm", RuntimeWarning, stacklevel=3)

    def thickness(points: np.ndarray) -> np.ndarray:
        return gap + slope * np.clip(points @ side - low, 0.0, width)

    return thickness


def _signed_distance_of(inside: np.ndarray, h: float) -> np.ndarray:
    """A grid set's signed distance [m] (negative inside), from the Euclidean distance transforms of it and of its
    complement on a grid of spacing ``h``: within about a spacing of the exact one."""
    from scipy import ndimage

    return np.where(inside, -ndimage.distance_transform_edt(inside, sampling=h),
                    ndimage.distance_transform_edt(~inside, sampling=h))


def _cover_on_grid(mesh: trimesh.Trimesh, kind: str, gap: float, bridge: float, h: float, lo: np.ndarray,
                   hi: np.ndarray, thickness=None) -> trimesh.Trimesh:
    """:func:`cover_around`'s surface meshed on the grid of spacing ``h`` from ``lo`` to ``hi`` [m] (``thickness``:
    the uneven cover's gap, points -> [m])."""
    from scipy import ndimage
    from skimage import measure

    from .meshes import MeshDistance

    axes = [np.arange(a, b + h / 2, h) for a, b in zip(lo, hi)]
    shape = tuple(len(a) for a in axes)
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    d = MeshDistance(mesh)(grid).reshape(shape)
    field = d - (gap if thickness is None else thickness(grid).reshape(shape))
    if kind in ("loose", "hanging"):
        grown = d <= gap + bridge
        inside = ndimage.distance_transform_edt(grown, sampling=h)
        outside = ndimage.distance_transform_edt(~grown, sampling=h)
        closing = np.where(grown, bridge - inside, bridge + outside)      # > 0 outside the closed set
        field = np.minimum(field, closing)
    if kind == "hanging":
        # every node below a node of the cover, down to the table (the body's lowest point, less the gap under it);
        # only what the hanging adds takes the distance transform's field, so the cover keeps its exact level set
        # where it lies on the body
        cover = field < -h * _LEVEL_OFFSET           # inside as marching cubes below counts it
        hangs = np.flip(np.logical_or.accumulate(np.flip(cover, axis=2), axis=2), axis=2)
        hangs &= (axes[2] >= mesh.bounds[0, 2] - gap)[None, None, :]
        added = hangs & ~cover
        if added.any():
            field = np.minimum(field, _signed_distance_of(added, h))
    # the level a hair off zero: the loose cover's erosion is an exact distance transform, whose values are lattice
    # distances sqrt(k) h; where the bridge is a whole number of cells (3 cm on the 3 mm grid of a 24 cm carton) many
    # nodes lie exactly on the level, marching cubes gives zero-area triangles there, and the mesh without them is
    # open on every shifted grid. An irrational thousandth of a cell (a micrometre) moves the surface by nothing one can
    # measure, and keeps the vertices apart by more than trimesh merges.
    verts, faces, _, _ = measure.marching_cubes(field, level=-h * _LEVEL_OFFSET, spacing=(h,) * 3,
                                                gradient_direction="descent")
    out = trimesh.Trimesh(verts + lo, faces, process=True)
    out.update_faces(out.nondegenerate_faces())
    out.remove_unreferenced_vertices()
    trimesh.repair.fix_normals(out)
    return out


def first_passage(inner: trimesh.Trimesh, distance, start, direction) -> tuple[float, float] | None:
    """Where the ray from ``start`` `(3,)` along ``direction`` `(3,)` first enters the closed ``inner`` mesh,
    and how deep its first passage through it goes.

    Args:
        inner: the closed body mesh [m].
        distance: its signed distance, `(n, 3)` points -> `(n,)` [m], negative inside.
        start: `(3,)` the ray's origin [m].
        direction: `(3,)` its direction (normalised here).

    Returns:
        ``(t, depth)``: the distance [m] along the ray to the entry, and the deepest point of the chord to the next
        crossing [m] (41 samples; ``inf`` when the ray crosses the surface once, e.g. from inside); None when the
        ray misses.

    Raises:
        ValueError: a start or direction that is not a finite 3-vector, or a zero direction.
    """
    start, direction = np.asarray(start, dtype=np.float64), np.asarray(direction, dtype=np.float64)
    finite = np.isfinite(start).all() and np.isfinite(direction).all()
    if start.shape != (3,) or direction.shape != (3,) or not finite:
        raise ValueError(f"first_passage: start and direction must be finite (3,) vectors, got {start!r}, "
                         f"{direction!r}")
    length = float(np.linalg.norm(direction))
    if length == 0.0:
        raise ValueError("first_passage: direction is the zero vector")
    if abs(length - 1.0) > 1e-12:
        direction = direction / length
    hits, _, _ = inner.ray.intersects_location(start[None], direction[None], multiple_hits=True)
    if len(hits) == 0:
        return None
    t = np.sort(np.linalg.norm(hits - start, axis=1))
    if len(t) < 2:
        return float(t[0]), math.inf
    chord = start + np.linspace(t[0], t[1], 41)[:, None] * direction
    return float(t[0]), -float(np.min(distance(chord)))


def approach_from_above(inner: trimesh.Trimesh, outer: trimesh.Trimesh, clearance: float = 0.08,
                        margin: float = 0.03) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A default approach and range for an object on a table: straight down onto the body point nearest the centre
    of its top view (rays cast on a grid, so a ring's hole, where a ray meets nothing, is never aimed at; a cup's
    opening is: its ray meets the inside bottom, so give a cup a side approach) whose first passage through the body
    is at least ``Scene3D.MIN_APPROACH_DEPTH`` deep (:func:`first_passage`; not a thin lip), starting
    ``clearance`` above the cover; where every ray from above first passes a part too thin to feel, from the side
    (:func:`_side_approach`). The range is the cover's bounding box grown by ``margin`` [m], from a quarter of the
    body's height up (the part a camera and a fingertip reach on a table), to 1 cm short of the start.

    Returns:
        ``(start (3,), direction (3,), bounds (2, 3))`` [m].

    Raises:
        ValueError: no downward ray hits the body.
    """
    from .meshes import MeshDistance

    lo, hi = inner.bounds
    centre = (lo + hi) / 2
    u = np.linspace(-0.4, 0.4, 9)
    xy = np.stack(np.meshgrid(u, u, indexing="ij"), -1).reshape(-1, 2) * (hi - lo)[:2] + centre[:2]
    xy = xy[np.argsort(np.linalg.norm(xy - centre[:2], axis=1), kind="stable")]
    top = outer.bounds[1, 2] + clearance
    down = np.array([0.0, 0.0, -1.0])
    origins = np.c_[xy, np.full(len(xy), top)]
    hit = inner.ray.intersects_any(origins, np.broadcast_to(down, origins.shape))
    if not hit.any():
        raise ValueError("no downward ray hits the body: give start and direction")
    # the ray nearest the centre whose first passage through the body is deep enough to be felt (a ray through a
    # thin lip or the sliver where two pieces of a blob meet passes through without a contact); if none is, the
    # nearest that hits, and the scene says that its approach grazes
    distance = MeshDistance(inner)
    felt = _first_felt(inner, distance, origins, down, hit)
    start = origins[int(np.argmax(hit)) if felt is None else felt]
    if felt is None:
        # no ray from above is deep enough: a body too thin anywhere to be felt says so (pieces of thin sheets: 6 of
        # pybullet's procedural objects 200-299, 1-3 mm thick at most), not "the approach grazes"
        inside, depth = _deepest_samples(inner, distance)
        thickest = max(0.0, float(depth[0]))
        if thickest < Scene3D.MIN_APPROACH_DEPTH:
            raise ValueError(f"the body is nowhere more than {thickest * 1e3:.1f} mm inside its surface (thin sheets, "
                             f"{len(inner.split(only_watertight=False))} pieces): a fingertip needs "
                             f"{Scene3D.MIN_APPROACH_DEPTH * 1e3:.0f} mm to feel it from any side")
        # thick somewhere, but every ray from above first passes a thin part (a sheet over the body, a blob's fin):
        # from the side, at the body's middle height first (pybullet's blob 127: 0.4 mm deep at most from above);
        # none deep enough either: the scene then says that the approach from above grazes
        side = _side_approach(inner, outer, distance, clearance)
        if side is None:                # thick only where neither grid looks: at the thick part, from outside it
            side = _thick_part_approach(inner, outer, distance, clearance,
                                        inside[depth > Scene3D.MIN_APPROACH_DEPTH][:THICK_CANDIDATES])
        if side is not None:
            start, down = side
    b_lo, b_hi = outer.bounds[0] - margin, outer.bounds[1] + margin
    b_lo[2] = lo[2] + 0.25 * (hi[2] - lo[2])
    axis = int(np.argmax(np.abs(down)))        # the range reaches to 1 cm short of the start along the approach
    if down[axis] < 0:
        b_hi[axis] = max(b_hi[axis], start[axis] - 0.01)
    else:
        b_lo[axis] = min(b_lo[axis], start[axis] + 0.01)
    return start, down, np.stack([b_lo, b_hi])


def _side_approach(inner: trimesh.Trimesh, outer: trimesh.Trimesh, distance,
                   clearance: float) -> tuple[np.ndarray, np.ndarray] | None:
    """A horizontal approach (along +-x, +-y) whose first passage through the body is at least
    ``Scene3D.MIN_APPROACH_DEPTH`` deep, starting ``clearance`` outside the cover's box: of the rays on a grid over
    each side view (heights from a third to nine tenths of the body's, across its middle 80 %), the one nearest the
    middle of its view, the directions tried in turn; ``(start (3,), direction (3,))`` [m], or None."""
    lo, hi = inner.bounds
    centre = (lo + hi) / 2
    o_lo, o_hi = outer.bounds
    for axis, sign in ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0)):
        d = np.zeros(3)
        d[axis] = sign
        across = 1 - axis
        a = centre[across] + np.linspace(-0.4, 0.4, 9) * (hi[across] - lo[across])
        z = lo[2] + np.linspace(1 / 3, 0.9, 9) * (hi[2] - lo[2])
        grid = np.stack(np.meshgrid(a, z, indexing="ij"), -1).reshape(-1, 2)
        grid = grid[np.argsort(np.hypot(grid[:, 0] - centre[across], grid[:, 1] - (lo[2] + hi[2]) / 2),
                               kind="stable")]
        origins = np.zeros((len(grid), 3))
        origins[:, across], origins[:, 2] = grid[:, 0], grid[:, 1]
        origins[:, axis] = (o_lo[axis] - clearance) if sign > 0 else (o_hi[axis] + clearance)
        felt = _first_felt(inner, distance, origins, d,
                           inner.ray.intersects_any(origins, np.broadcast_to(d, origins.shape)))
        if felt is not None:
            return origins[felt], d
    return None


def _first_felt(inner: trimesh.Trimesh, distance, origins: np.ndarray, direction: np.ndarray,
                hit: np.ndarray) -> int | None:
    """The first of the rays from `(n, 3)` ``origins`` along ``direction`` that hit the body (``hit``, `(n,)` bool)
    whose first passage through it is at least ``Scene3D.MIN_APPROACH_DEPTH`` deep (:func:`first_passage`), or
    None."""
    for i in np.flatnonzero(hit):
        passage = first_passage(inner, distance, origins[i], direction)
        if passage is not None and passage[1] >= Scene3D.MIN_APPROACH_DEPTH:
            return int(i)
    return None


def _deepest_samples(inner: trimesh.Trimesh, distance, samples: int = 20000) -> tuple[np.ndarray, np.ndarray]:
    """``samples`` seeded points uniform in the body's box, deepest inside it first: `(samples, 3)` [m] and how deep
    each lies inside `(samples,)` [m] (negative outside). The first depth is about half the body's greatest thickness
    (a lower bound, to a few tenths of a millimetre at 20,000 points in a 20 cm box)."""
    lo, hi = inner.bounds
    points = lo + np.random.default_rng(0).uniform(size=(samples, 3)) * (hi - lo)
    depth = -distance(points)
    order = np.argsort(-depth, kind="stable")
    return points[order], depth[order]


#: The deepest points inside a body that :func:`_thick_part_approach` aims at, deepest first.
THICK_CANDIDATES = 200


def _thick_part_approach(inner: trimesh.Trimesh, outer: trimesh.Trimesh, distance, clearance: float,
                         deepest: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """An approach to the body's thick part where neither the grid from above nor those from the sides meet one (a
    blob whose thick piece sits at a corner or above nine tenths of its height, beside thin sheets): at each of the
    deepest seeded points inside it (``deepest`` `(k, 3)` [m], deepest first: :func:`_deepest_samples`' more than
    ``Scene3D.MIN_APPROACH_DEPTH`` inside, at most :data:`THICK_CANDIDATES`), from above and then along +-x and +-y
    (the directions the arm takes the other approaches in), starting ``clearance`` outside the cover's box; the first
    whose first passage is at least ``Scene3D.MIN_APPROACH_DEPTH`` deep. ``(start (3,), direction (3,))`` [m], or
    None."""
    o_lo, o_hi = outer.bounds
    directions = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    for p in deepest:
        for d in directions:
            axis = int(np.argmax(np.abs(d)))
            start = p.copy()
            start[axis] = (o_lo[axis] - clearance) if d[axis] > 0 else (o_hi[axis] + clearance)
            passage = first_passage(inner, distance, start, d)
            if passage is not None and passage[1] >= Scene3D.MIN_APPROACH_DEPTH:
                return start, d
    return None


def sphere_scene(radius: float = 0.08, cover: float = 0.01, center=(0.5, 0.0, 0.25), name: str = "sphere",
                 subdivisions: int = 4) -> Scene3D:
    """A sphere under a uniform cover, approached from above; the exploration range is its upper half.

    Args:
        radius: inner radius [m]. cover: cover thickness [m]. center: `(3,)` [m], base frame.
    """
    c = np.asarray(center, dtype=np.float64)
    inner = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    outer = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius + cover)
    inner.apply_translation(c)
    outer.apply_translation(c)
    reach = radius + cover + 0.05
    bounds = np.stack([c - reach, c + reach])
    bounds[0, 2] = c[2] - 0.3 * radius
    return Scene3D(inner, outer, start=c + [0.01, 0.005, reach + 0.05], direction=(0, 0, -1), bounds=bounds,
                   name=name)


def paper_objects_3d(resolution: float = 0.006) -> dict[str, Scene3D]:
    """Objects E-H of the robot experiment (Sec. VI, Fig. 6), built from capsules and rounded boxes [m].

    * E, arm in a tight sleeve: an upper arm (r = 5 cm) and a forearm (r = 4 cm) capsule blended at the elbow,
      lying along y at 25 cm height, bent 18 deg at the elbow; the sleeve is the arm grown by 8 mm.
    * F, arm in a loose sleeve: the same arm; the sleeve is a 9 cm tube along the upper arm and forearm axes,
      sagging 2.5 cm, blended with the arm grown by 1 cm. The arm's shape stays recognisable.
    * G, torso in a tight shirt: a chest (rounded box 18 x 30 x 36 cm), shoulders (capsule, r = 6 cm) and a neck
      (capsule, r = 4.5 cm) blended; the shirt is the torso grown by 8 mm.
    * H, torso in a loose garment: the same torso under a poncho, a rounded box 34 x 52 x 48 cm with 8 cm edge
      radius, blended with the torso grown by 1 cm (neck and shoulders shape the top, the rest hangs).

    The arm is approached from above, the torso from the front (the side facing the robot base). The
    exploration range is the upper half of the arm and the front and top of the torso, as in Fig. 6. The
    inner-outer Hausdorff distances are in docs/results-3d.md (``Scene3D.inner_outer_hausdorff``).

    Args:
        resolution: marching-cubes grid spacing of the meshes [m].
    """
    elbow = np.array([0.5, 0.02, 0.25])
    hand = elbow + 0.19 * np.array([-math.sin(math.radians(18)), math.cos(math.radians(18)), 0.0])
    shoulder = np.array([0.5, -0.21, 0.25])
    arm = smooth_union(capsule(shoulder, elbow, 0.05), capsule(elbow, hand, 0.04), k=0.03)
    sag = np.array([0.0, 0.0, -0.025])
    sleeve = smooth_union(offset(arm, 0.01), capsule(shoulder + sag, elbow + sag, 0.09),
                          capsule(elbow + sag, hand + 0.6 * sag, 0.075), k=0.04)
    arm_box = [[0.25, -0.40, 0.05], [0.75, 0.40, 0.45]]
    arm_mesh = mesh_from_sdf(arm, arm_box, resolution)
    arm_range = [[0.36, -0.24, 0.24], [0.66, 0.24, 0.42]]
    arm_start, down = (0.51, -0.06, 0.45), (0.0, 0.0, -1.0)

    torso = smooth_union(rounded_box((0.62, 0.0, 0.24), (0.09, 0.15, 0.18), 0.06),
                         capsule((0.62, -0.14, 0.40), (0.62, 0.14, 0.40), 0.06),
                         capsule((0.62, 0.0, 0.42), (0.62, 0.0, 0.53), 0.045), k=0.05)
    poncho = smooth_union(offset(torso, 0.01), rounded_box((0.62, 0.0, 0.25), (0.17, 0.26, 0.24), 0.08), k=0.03)
    torso_box = [[0.32, -0.4, -0.1], [0.92, 0.4, 0.62]]
    torso_mesh = mesh_from_sdf(torso, torso_box, resolution)
    torso_range = [[0.34, -0.24, 0.10], [0.62, 0.24, 0.56]]
    torso_start, forward = (0.34, 0.03, 0.27), (1.0, 0.0, 0.0)

    return {
        "E": Scene3D(arm_mesh, mesh_from_sdf(offset(arm, 0.008), arm_box, resolution), arm_start, down,
                     arm_range, name="E"),
        "F": Scene3D(arm_mesh, mesh_from_sdf(sleeve, arm_box, resolution), arm_start, down, arm_range, name="F",
                     cover_stiffness=3.0),
        "G": Scene3D(torso_mesh, mesh_from_sdf(offset(torso, 0.008), torso_box, resolution), torso_start, forward,
                     torso_range, name="G"),
        "H": Scene3D(torso_mesh, mesh_from_sdf(poncho, torso_box, resolution), torso_start, forward,
                     torso_range, name="H", cover_stiffness=3.0),
    }


def _scene_from_file(mesh, kind: str, *, name: str, where: dict, cover: dict, settings: dict, preset: str | None,
                     smoke: bool) -> Scene3D:
    """A scene file's world (:mod:`torch_gpioius.sim.scenefile`): :meth:`Scene3D.from_mesh` with the file's values;
    ``preset`` replaces the file's ``settings``; ``smoke`` changes nothing here (the cover is static)."""
    if preset is not None:
        settings = dict(settings, settings=preset)
    # the section's estimator settings (the scene format keeps them beside the world's own) as one object
    loose = {k: settings.pop(k) for k in ESTIMATOR_KEYS if k in settings}
    return Scene3D.from_mesh(mesh, kind, name=name, **where, **cover, **settings,
                             estimator=estimator_changes(**loose) if loose else None)


#: What a scene file's ``[cover]`` and ``[forcefield]`` sections may hold in this world.
SCENE_SUPPORT = SceneSupport(
    cover_keys=frozenset({"gap", "bridge", "resolution", "gap_far", "thick_side"}), cover_kinds=COVER_KINDS,
    settings_keys=frozenset({"cover_stiffness", "sensor_noise", "settings", "views", "kernel", "lengthscale", "theta",
                             "noise", "voxel", "touch_inside", "vision_inside", "vision_inside_gap", "cover_offset",
                             "learn", "camera_error"}),
    build=_scene_from_file)

register_world("forcefield", Scene3D, objects=lambda names, smoke: paper_objects_3d(0.01 if smoke else 0.006),
               object_names=("E", "F", "G", "H"), dimension=3, scene=SCENE_SUPPORT, presets=True,
               description="Sec. VI in 3-D: a kinematic UR5, a force-field cover that does not move (objects E-H)")
