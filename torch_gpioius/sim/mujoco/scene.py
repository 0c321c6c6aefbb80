"""The MuJoCo world: a UR5 with a compliant fingertip force sensor, a rigid inner object (primitives or any closed
mesh), and a cloth or foam cover that the fingertip pushes aside, on MuJoCo's contact physics.

Everything the loop uses goes through the interfaces of :mod:`torch_gpioius.exploration.world`: the robot
(:class:`MujocoUR5`, behind the same ``SafetyGate`` as every backend), the force sensor (:class:`MujocoForceSensor`),
the camera (:class:`MujocoDepthCamera`, seeing the settled cover) and the unchanged
:class:`torch_gpioius.exploration.contact.ContactController`. Metrics use the exact signed distance of the body
(:mod:`~torch_gpioius.sim.mujoco.bodies`: the primitives' union, or the mesh itself).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ...models.estimator import EstimatorSettings
from ...exploration.stopping import TravelBudget
from ...exploration.world import (ContactTruth, ExplorationDefaults, Hardware, Measurement, geometry_hash,
                                  perturbed_approaches)
from ...core.validation import as_bounds
from .covers import COVER_KINDS, CoverMesh, cap_base, cover_flexcomp, make_cover, shrink_wrap, tube_base
from .bodies import MeshBody, PrimitiveBody, as_body
from .primitives import as_primitives
from ..ranged import RangedScene

__all__ = ["MujocoScene", "MUJOCO_DEFAULTS", "SCENE_LIMITS", "MAX_PRIMITIVES", "MAX_COVER_VERTICES"]

#: Accepted ranges of the scene's numeric options, ``name: (lo, hi, unit)``: outside them MuJoCo either cannot
#: compile the model, divides by zero, or needs gigabytes or hours (``camera_scale=50`` asked for 4 GiB,
#: ``settle_time=1e5`` for days of simulation).
SCENE_LIMITS = {"sensor_noise": (0.0, 1.0, "N"), "timestep": (1e-4, 0.01, "s"), "settle_time": (0.0, 10.0, "s"),
                "camera_scale": (0.05, 1.0, ""), "tool_length": (0.01, 0.3, "m"), "tip_radius": (0.001, 0.02, "m"),
                "spacing": (0.005, 0.1, "m"), "half_angle": (1.0, 180.0, "deg")}
#: Most primitives or convex parts in one inner object (500 primitives blew up at the first step).
MAX_PRIMITIVES = 64
#: Most cover vertices (a 1 mm spacing asked MuJoCo for more memory than its arena has).
MAX_COVER_VERTICES = 20_000


def _limited(value, name: str) -> float:
    from ...core.validation import as_float

    lo, hi, unit = SCENE_LIMITS[name]
    return as_float(value, name, lo=lo, hi=hi, unit=unit)

#: The robot study's settings in the MuJoCo world (as the force-field world's; the camera at half Kinect resolution).
MUJOCO_DEFAULTS = ExplorationDefaults(step=0.01, max_steps=400, stop=(TravelBudget(1.5),), metrics_every=1,
                                      approach_travel=0.5, estimator=EstimatorSettings.paper())


def _require_mujoco():
    try:
        import mujoco  # noqa: F401
    except ImportError as exc:   # pragma: no cover - depends on the environment
        from ...core.extras import install_hint

        raise ImportError(f"the MuJoCo world needs the 'mujoco' package: {install_hint('mujoco')}") from exc


class MujocoScene(RangedScene):
    """A covered object on MuJoCo's physics, explored by a simulated UR5 with a fingertip force sensor.

    Build it with :meth:`from_primitives` or :meth:`from_mesh`. On construction the model is compiled, the arm placed
    at the start (its fingertip at ``start``, pointing along ``direction``), and the cover settled under gravity; every
    :meth:`hardware` call starts from that settled state.

    Why this many parameters: the scene's objects, its approach and range, and the simulation's step, noise and
    views are each fixed by the physics or the rig, not by one another.

    Args:
        inner: the inner object: a :class:`~torch_gpioius.sim.mujoco.bodies.PrimitiveBody` or
            :class:`~torch_gpioius.sim.mujoco.bodies.MeshBody`, or primitives
            (:func:`torch_gpioius.sim.mujoco.primitives.as_primitives`).
        cover: the :class:`~torch_gpioius.sim.mujoco.covers.CoverMesh`.
        start: `(3,)` fingertip start [m], outside the cover.
        direction: `(3,)` approach direction.
        bounds: `(2, 3)` exploration range `[min corner; max corner]` [m].
        name: label.
        seed: seed of the sensor and camera noise.
        sensor_noise: force noise per axis [N] (OptoForce OMD-20: ~0.02 N).
        timestep: physics timestep [s].
        settle_time: simulated time the cover settles before exploring [s].
        camera_scale: image scale of the Kinect v2 model.
        defaults: overrides of :data:`MUJOCO_DEFAULTS`.
        views: the camera's views of the settled scene, as the force-field world's
            (:data:`torch_gpioius.sim.forcefield.VIEWS`: names, a count or "paper"; default: the fixed camera alone,
            the paper's): "fixed" behind the approach, 30 cm to one side, 30 cm up; "mirrored", its mirror image to
            the other side; "wrist", a short-range depth camera 35 cm back from the body along the approach, captured
            before the first touch. The tripods stand where the unperturbed approach put them: a seed's perturbation
            moves the arm, and with it the wrist view, not them.

    Raises:
        ImportError: MuJoCo is not installed (names the extra).
        ValueError: a start inside the cover, a cover that intersects the body at rest, bad bounds.
        MujocoInstability: the cover does not settle (NaN or runaway energy).
    """

    dim = 3

    def __init__(self, inner, cover: CoverMesh, start, direction, bounds, *, name: str = "",
                 seed: int = 0, sensor_noise: float = 0.02, timestep: float = 0.008, settle_time: float = 1.0,
                 camera_scale: float = 0.5, defaults: ExplorationDefaults | None = None,
                 tool_length: float = 0.05, tip_radius: float = 0.004, views="paper", camera_error=None) -> None:
        from ...sensors.simulated.camera import CameraError
        from ..presets import as_views

        _require_mujoco()
        self.views = as_views(views)
        self.camera_error = CameraError.parse(camera_error if camera_error is not None else CameraError())
        self.body = as_body(inner)
        if len(self.body) > MAX_PRIMITIVES:
            raise ValueError(f"inner: {len(self.body)} primitives or parts; at most {MAX_PRIMITIVES} are supported")
        if len(cover.vertices) > MAX_COVER_VERTICES:
            raise ValueError(f"cover: {len(cover.vertices)} vertices; at most {MAX_COVER_VERTICES} (a coarser spacing)")
        if not isinstance(name, str):
            raise ValueError(f"name: expected a string, got {name!r}")
        sensor_noise, timestep, settle_time, camera_scale, tool_length, tip_radius = (
            _limited(v, k) for v, k in ((sensor_noise, "sensor_noise"), (timestep, "timestep"),
                                        (settle_time, "settle_time"), (camera_scale, "camera_scale"),
                                        (tool_length, "tool_length"), (tip_radius, "tip_radius")))
        self.cover = cover
        #: the primitives of a primitive body ([] for a mesh body)
        self.primitives = list(getattr(self.body, "primitives", []))
        self.start = np.asarray(start, dtype=np.float64).reshape(-1)
        d = np.asarray(direction, dtype=np.float64).reshape(-1)
        if self.start.shape != (3,) or not np.isfinite(self.start).all():
            raise ValueError(f"start: expected a finite (3,) position [m], got {start!r}")
        if d.shape != (3,) or not np.isfinite(d).all() or np.linalg.norm(d) == 0:
            raise ValueError("direction: must be a finite non-zero 3-vector")
        self.direction = d / np.linalg.norm(d)
        self._tripod_direction = self.direction         # perturbed() carries the unperturbed one over
        self.range = as_bounds(bounds, 3)
        self.name, self.seed = name, int(seed)
        self.sensor_noise, self.timestep, self.settle_time = float(sensor_noise), float(timestep), float(settle_time)
        self.camera_scale, self.tool_length, self.tip_radius = (
            float(camera_scale),
            float(tool_length),
            float(tip_radius),
        )
        self._defaults = defaults or MUJOCO_DEFAULTS
        self._inner_samples: dict[float, np.ndarray] = {}
        # the cover must start outside the body (its elements' radius included)
        depth = self.body.collision_sdf(cover.vertices) - cover.radius
        if depth.min() < -1e-9:
            raise ValueError(f"cover: intersects the body at rest ({-depth.min() * 1e3:.1f} mm deep at vertex "
                             f"{int(depth.argmin())}); give it more gap or slack")
        if self.body.sdf(self.start[None])[0] <= 0:
            raise ValueError("start: lies inside the inner object")
        self._build()

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_primitives(cls, inner, cover: str = "loose", start=None, direction=None, bounds=None, *,
                        name: str = "", seed: int = 0, base: str = "auto", spacing: float = 0.025,
                        axis=None, centre=None, facing=None, half_angle: float = 100.0, **cover_options
                        ) -> "MujocoScene":
        """A MuJoCo scene from primitives and a cover kind.

        Args:
            inner: list of ``{"type", "size", "pos", "quat"}`` in MuJoCo's conventions (SI, base frame, w-x-y-z).
            cover: "tight" (a cloth shell ``gap`` off the body), "loose" (a cloth built ``slack`` off the body that
                settles under gravity) or "foam" (a soft 3-D shell of ``thickness``).
            start: `(3,)` fingertip start [m], outside the cover; direction: `(3,)` approach direction.
            bounds: `(2, 3)` exploration range `[min corner; max corner]` [m].
            base: how the cover is shaped: "tube" (around ``axis``, a polyline `(k, 3)`: limbs), "cap" (around
                ``centre``, facing ``facing`` within ``half_angle`` degrees: torsos), or "auto" (a tube along the
                primitives' longest extent when ``axis`` is given, else a cap facing the approach).
            spacing: cloth vertex spacing [m].
            **cover_options: ``gap``, ``slack``, ``thickness``, ``radius``, ``young``, ``poisson``, ``damping``,
                ``density`` (:func:`~torch_gpioius.sim.mujoco.covers.make_cover`), and the scene's keywords
                (``sensor_noise``, ``timestep``, ``settle_time``, ``camera_scale``, ``defaults``).

        Raises:
            ValueError: a primitive with a non-positive size, an unknown cover, missing start / direction / bounds.
        """
        _require_mujoco()
        prims = as_primitives(inner)
        if len(prims) > MAX_PRIMITIVES:
            raise ValueError(f"inner: {len(prims)} primitives; at most {MAX_PRIMITIVES} are supported")
        return cls._around(PrimitiveBody(prims), cover, start, direction, bounds, name=name, seed=seed, base=base,
                           spacing=spacing, axis=axis, centre=centre, facing=facing, half_angle=half_angle,
                           **cover_options)

    @classmethod
    def from_mesh(cls, inner, cover: str = "loose", *, start, direction, bounds, pose=None, scale: float = 1.0,
                  repair: bool = True, collision: str = "convex", threshold: float = 0.05, max_parts: int = 32,
                  name: str = "", seed: int = 0, base: str = "cap", spacing: float | None = None, axis=None,
                  centre=None, facing=None, half_angle: float = 100.0, **cover_options) -> "MujocoScene":
        """A MuJoCo scene around any closed mesh: a user's scan or CAD model as the hidden body.

        Why this many parameters: the body's pose, its collision model and the cover's base and shape are each a few
        numbers a user's object needs; the cloth's own physics go through ``cover_options`` (:meth:`from_primitives`).

        The mesh is loaded, checked and, if it is open or non-manifold, repaired with a warning that states how far
        the repair moved the surface (:func:`torch_gpioius.sim.meshes.load_mesh`); it collides as CoACD convex parts
        (:class:`~torch_gpioius.sim.mujoco.bodies.MeshBody`) and every metric uses the exact distance to the mesh.

        Args:
            inner: a ``trimesh.Trimesh`` or a path (STL, OBJ, PLY, GLB) [m after ``scale``].
            cover: "tight", "loose" or "foam" (as :meth:`from_primitives`).
            start: `(3,)` fingertip start [m], outside the cover; direction: `(3,)` approach direction.
            bounds: `(2, 3)` exploration range `[min corner; max corner]` [m].
            pose: where the object stands (`(4, 4)` or ``{"position", "quat" | "rpy_deg"}``), after ``scale``.
            scale: factor to metres (0.001 for millimetres).
            repair: repair an open mesh (False refuses it).
            collision: "convex" (CoACD parts) or "hull" (MuJoCo's hull of the whole mesh; convex objects only).
            threshold: CoACD's concavity threshold (smaller: more parts, closer to the mesh).
            max_parts: the most convex parts.
            name: label; seed: the scene's seed.
            base: "cap" (a garment facing ``facing``, default against the approach) or "tube" (around ``axis``).
            spacing: the cover's vertex spacing [m] (default: 1/12 of the object's largest extent, 1.2-2.5 cm).
            axis: the tube's axis polyline (as :meth:`from_primitives`).
            centre: the cap's centre (as :meth:`from_primitives`).
            facing: the cap's direction (as :meth:`from_primitives`).
            half_angle: the cap's half angle [deg] (as :meth:`from_primitives`).
            **cover_options: the cover's and scene's options (as :meth:`from_primitives`).

        Raises:
            ValueError: an unreadable, empty or irreparable mesh (the message names the defect), and everything
                :meth:`from_primitives` refuses.
        """
        from ..meshes import load_mesh

        _require_mujoco()
        mesh = load_mesh(inner, scale=scale, pose=pose, repair=repair, name="inner")
        body = MeshBody(mesh, collision, threshold=threshold, max_parts=max_parts)
        if spacing is None:
            spacing = float(np.clip(float(mesh.extents.max()) / 12, 0.012, 0.025))
        return cls._around(body, cover, start, direction, bounds, name=name, seed=seed, base=base, spacing=spacing,
                           axis=axis, centre=centre, facing=facing, half_angle=half_angle, **cover_options)

    @classmethod
    def _around(cls, body, cover: str, start, direction, bounds, *, name: str, seed: int, base: str, spacing,
                axis, centre, facing, half_angle, **cover_options) -> "MujocoScene":
        """A scene with a cover of ``cover`` built around ``body``."""
        spacing, half_angle = _limited(spacing, "spacing"), _limited(half_angle, "half_angle")
        if cover not in COVER_KINDS:
            raise ValueError(f"cover: must be one of {COVER_KINDS}, got {cover!r}")
        if start is None or direction is None or bounds is None:
            raise ValueError("from_primitives: start, direction and bounds are required")
        scene_kw = {k: cover_options.pop(k) for k in ("sensor_noise", "timestep", "settle_time", "camera_scale",
                                                      "defaults", "views") if k in cover_options}
        if base == "auto":
            base = "tube" if axis is not None else "cap"
        if base == "tube":
            if axis is None:
                raise ValueError("base='tube' needs axis, a (k, 3) polyline along the limb")
            mesh_base = tube_base(axis, spacing)
        elif base == "cap":
            c = body.centre if centre is None else np.asarray(centre, dtype=np.float64)
            f = -np.asarray(direction, dtype=np.float64) if facing is None else np.asarray(facing, dtype=np.float64)
            # the typical distance of the surface from the centre, along a few directions of the cap
            probe = cap_base(c, f, half_angle, 1.0, 1.0)
            radius = float(np.median(np.linalg.norm(shrink_wrap(body, *probe[:2], 0.0) - c, axis=1)))
            mesh_base = cap_base(c, f, half_angle, spacing, radius)
        else:
            raise ValueError(f"base: must be 'auto', 'tube' or 'cap', got {base!r}")
        if len(mesh_base[0]) * (2 if cover == "foam" else 1) > MAX_COVER_VERTICES:
            raise ValueError(f"spacing: {spacing:g} m gives a cover of {len(mesh_base[0])} vertices; at most "
                             f"{MAX_COVER_VERTICES} are supported (use a coarser spacing)")
        mesh = make_cover(body, cover, mesh_base, **cover_options)
        return cls(body, mesh, start, direction, bounds, name=name, seed=seed, **scene_kw)

    def _xml(self) -> str:
        from .ur5 import ur5_mjcf

        body, actuators, sensors = ur5_mjcf(tool_offset=(0.0, 0.0, self.tool_length), tip_radius=self.tip_radius)
        geoms = self.body.geoms()
        assets = self.body.assets()
        from xml.sax.saxutils import quoteattr

        return f"""<mujoco model={quoteattr(self.name or 'covered object')}>
<compiler angle="radian" autolimits="true"/>
<option timestep="{self.timestep}" solver="CG" cone="elliptic" tolerance="1e-6" integrator="discrete">
<flag energy="enable" autoreset="disable"/></option>
<size memory="64M"/>
{f"<asset>{assets}</asset>" if assets else ""}
<worldbody>
{geoms}
{cover_flexcomp(self.cover)}
{body}
</worldbody>
<actuator>{actuators}</actuator>
<sensor>{sensors}</sensor>
</mujoco>"""

    def _build(self) -> None:
        import mujoco

        from kinematics import UR5, tool_rotation

        from .hardware import MujocoPhysics

        self.model = mujoco.MjModel.from_xml_string(self._xml())
        physics = MujocoPhysics(self.model)
        self.ur5 = UR5(tool_offset=(0.0, 0.0, self.tool_length))
        T = torch.eye(4, dtype=torch.float64)
        T[:3, :3] = tool_rotation(self.direction)
        T[:3, 3] = torch.as_tensor(self.start)
        self.q_start = self.ur5.inverse_kinematics(
            T, q_init=torch.tensor([0.0, -1.2, 1.5, -1.9, -1.57, 0.0], dtype=torch.float64))
        robot = self._robot(physics)
        robot.place(self.q_start)
        physics.step(max(1, int(round(self.settle_time / self.timestep))))      # the cover settles
        self.settled = physics.get_state()
        verts = self.cover_vertices(physics)
        depth = self.body.sdf(verts) - 0.5 * self.cover.radius
        if depth.min() < -0.005:
            raise ValueError(f"cover: settles {-depth.min() * 1e3:.1f} mm into the body; it is too heavy or too soft "
                             "for its contact")
        # the start must lie outside the cover: looking back from the start (against the approach), nothing of
        # the cover may be there, and the fingertip must not touch it
        back = self._flex_ray(physics, self.start, -self.direction)
        if back is not None:
            raise ValueError("start: lies inside the cover (the cover is behind it along the approach); start "
                             "outside the cover")
        if np.linalg.norm(verts - self.start, axis=1).min() < self.tip_radius + self.cover.radius + 0.005:
            raise ValueError("start: touches the cover; start at least 5 mm outside it")
        self._physics0 = physics
        self._tip_geom = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, "fingertip")

    def _robot(self, physics):
        from kinematics import SafetyGate

        from .hardware import MujocoUR5

        lo = np.minimum(self.range[0], self.start) - 0.1
        hi = np.maximum(self.range[1], self.start) + 0.1
        return MujocoUR5(physics, self.ur5, SafetyGate(self.ur5, lo.tolist(), hi.tolist()))

    def _flex_ray(self, physics, origin, direction) -> float | None:
        import mujoco

        vid = np.zeros(1, np.int32)
        d = mujoco.mj_rayFlex(physics.model, physics.data, 0, False, False, True, False, 0,
                              np.asarray(origin, dtype=np.float64), np.asarray(direction, dtype=np.float64), vid, None)
        return None if d < 0 else float(d)

    def cover_vertices(self, physics=None) -> np.ndarray:
        """`(n, 3)` current cover vertex positions [m] (after settling when no physics is given)."""
        physics = physics or self._physics0
        return np.asarray(physics.data.flexvert_xpos, dtype=np.float64).copy()

    # ------------------------------------------------------------------ the World interface
    @property
    def defaults(self) -> ExplorationDefaults:
        return self._defaults

    def hardware(self) -> Hardware:
        from ...exploration.contact import ContactConfig, ContactController
        from .hardware import MujocoForceSensor, MujocoPhysics

        physics = MujocoPhysics(self.model)
        physics.set_state(self.settled)
        robot = self._robot(physics)
        robot._target = np.asarray(self.q_start.numpy(), dtype=np.float64)
        sensor = MujocoForceSensor(physics, noise_std=self.sensor_noise, seed=self.seed)
        sensor.tare()
        camera = self.cameras(physics, self.views)
        config = ContactConfig(speed=0.08, approach_step=0.003, tip_radius=self.tip_radius, tip_stiffness=1000.0)
        return Hardware(robot, sensor, camera, ContactController(robot, sensor, config),
                        self.tactile_pad(physics, robot, sensor))

    def cameras(self, physics, views=("fixed",)):
        """The depth cameras of ``views`` (see the class) ray-cast in ``physics``: the fixed one alone is one
        :class:`~torch_gpioius.sim.mujoco.hardware.MujocoDepthCamera` seeded by the scene's seed; several views are
        one :class:`~torch_gpioius.sensors.MultiViewSource` whose view k draws its noise from ``[seed, k]``."""
        from ...sensors.pointcloud import MultiViewSource, PinholeCamera, look_at
        from ..presets import as_views
        from .hardware import MujocoDepthCamera

        def tripod(seed, side: float):
            target = self.range.mean(axis=0)
            back = -self._tripod_direction
            across = np.cross(back, [0.0, 0.0, 1.0]) if abs(back[2]) < 0.9 else np.array([0.0, -1.0, 0.0])
            eye = target + back + side * 0.3 * across / np.linalg.norm(across) + np.array([0.0, 0.0, 0.3])
            eye = target + 1.1 * (eye - target) / np.linalg.norm(eye - target)
            return MujocoDepthCamera(physics, PinholeCamera.kinect_v2(self.camera_scale), look_at(eye, target),
                                     noise_a=0.0015, noise_b=0.0015, seed=seed, error=self.camera_error,
                                     error_key=self._error_key())

        def wrist(seed):
            target = self.first_contact()
            up = (0.0, 0.0, 1.0) if abs(self.direction[2]) < 0.9 else (1.0, 0.0, 0.0)
            return MujocoDepthCamera(physics, PinholeCamera.realsense_d405(0.25),
                                     look_at(target - 0.35 * self.direction, target, up), noise_a=0.0005,
                                     noise_b=0.002, seed=seed, error=self.camera_error, error_key=self._error_key())

        views = as_views(views)
        if views == ("fixed",):
            return tripod(self.seed, 1.0)
        make = {"fixed": lambda k: tripod([self.seed, k], 1.0), "mirrored": lambda k: tripod([self.seed, k], -1.0),
                "wrist": lambda k: wrist([self.seed, k])}
        return MultiViewSource([make[v](k) for k, v in enumerate(views)], views)

    def first_contact(self) -> np.ndarray:
        """`(3,)` where the approach line first meets the body [m] (every millimetre, by its exact distance); the
        point of the line nearest the range's centre if it misses within 1 m."""
        line, sdf = self._along(self.start, self.direction)
        inside = np.flatnonzero(sdf < 0)
        if len(inside):
            return line[inside[0]]
        return self.start + self.direction * float((self.range.mean(axis=0) - self.start) @ self.direction)

    def _along(self, start, direction, reach: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """`(n, 3)` points every millimetre of the line from ``start`` along ``direction`` for ``reach`` [m], and the
        body's exact signed distance `(n,)` at each."""
        d = np.asarray(direction, dtype=np.float64)
        line = np.asarray(start, dtype=np.float64) + np.arange(0.0, reach, 0.001)[:, None] * d / np.linalg.norm(d)
        return line, self.body.sdf(line)

    def with_settings(self, settings: str) -> "MujocoScene":
        """The same body, cover, approach and range under other exploration settings: "default"
        (:func:`~torch_gpioius.sim.forcefield.object_defaults` on this world's own: voxels a tenth of the body, a
        second free-space point, the Matérn-5/2 and inside points; all three views) or "paper"
        (:data:`MUJOCO_DEFAULTS`, the fixed camera alone). The cover settles again, to the same state.

        Raises:
            ValueError: an unknown setting.
        """
        from ..presets import settings_for

        return self._copy(self.start, self.direction, self.seed, **settings_for(settings, self.inner, MUJOCO_DEFAULTS))

    def with_estimator(self, estimator) -> "MujocoScene":
        """The same scene with other estimator settings: an :class:`~torch_gpioius.models.estimator.EstimatorSettings`
        in place of its own, or an :class:`~torch_gpioius.models.overrides.EstimatorOverrides` (or its plain dict: a
        scene file's ``[estimator]`` section) applied to its own. The cover settles again, to the same state.

        Raises:
            ValueError: anything else, or changes that do not hold together (named).
        """
        from ...models.overrides import resolved

        estimator = resolved(estimator, self.defaults.estimator)
        return self._copy(self.start, self.direction, self.seed, defaults=self.defaults.with_estimator(estimator))

    def with_views(self, views) -> "MujocoScene":
        """The same body, cover, approach, range and settings seen by other views
        (:func:`~torch_gpioius.sim.forcefield.as_views`: names, a count or "paper"); the tripods stand where they
        stood. The cover settles again, to the same state.

        Raises:
            ValueError: unknown views.
        """
        from ..presets import as_views

        return self._copy(self.start, self.direction, self.seed, views=as_views(views))

    def with_camera_error(self, error) -> "MujocoScene":
        """The same scene seen by cameras whose calibration is off (as
        :meth:`torch_gpioius.sim.forcefield.Scene3D.with_camera_error`: each view of each run draws a rigid error of
        these sizes, ``"6mm,1deg"``; :meth:`camera_errors` says what each applies). The cover settles again, to the
        same state.

        Raises:
            ValueError: a malformed error.
        """
        from ...sensors.simulated.camera import CameraError

        return self._copy(self.start, self.direction, self.seed, camera_error=CameraError.parse(error))

    def _error_key(self) -> tuple:
        from ...sensors.simulated.camera import error_key

        return error_key(self.name)

    def camera_errors(self) -> dict[str, dict]:
        """The extrinsic error each view of this scene (its seed) applies, by view name; empty without one (drawn as
        the cameras draw it, without building them)."""
        from ...sensors.simulated.camera import view_errors

        return view_errors(self.camera_error, self.views, self.seed, self._error_key())

    def _copy(self, start, direction, seed: int, **changes) -> "MujocoScene":
        kw = dict(name=self.name, seed=seed, sensor_noise=self.sensor_noise, timestep=self.timestep,
                  settle_time=self.settle_time, camera_scale=self.camera_scale, defaults=self._defaults,
                  tool_length=self.tool_length, tip_radius=self.tip_radius, views=self.views,
                  camera_error=self.camera_error)
        scene = MujocoScene(self.body, self.cover, start, direction, self.range, **{**kw, **changes})
        scene._tripod_direction = self._tripod_direction
        return scene

    def tactile_pad(self, physics, robot, sensor):
        """A DIGIT-like gel pad at the fingertip (:class:`~torch_gpioius.sensors.simulated.gelpad.SimulatedGelPad`): it
        faces the fingertip's noiseless contact force and sees the body through the cloth where the simulated cloth lies
        between pad and body (rays against the cover's current faces), or the cover alone where the cover carries
        the force. Pinched cloth reads as its fabric thickness (1 mm); the simulated cloth counts as pinched within
        its collision layer (two element radii) + 1 mm of the body, as :meth:`contact_truth` counts it; foam,
        thicker than the gel, is read as foam."""
        from ...sensors.simulated.gelpad import SimulatedGelPad

        lift = self.cover.radius  # mj_rayFlex meets the faces' mid-surface; the cloth's face is this in front

        def cover_rays(origins: np.ndarray, axis: np.ndarray, far: float) -> np.ndarray:
            hits = (self._flex_ray(physics, o, axis) for o in origins)
            return np.array([d - lift if d is not None and d <= far else np.inf for d in hits])

        tip = self._tip_geom
        return SimulatedGelPad(self.body.sdf, lambda: np.array(physics.data.geom_xpos[tip]),
                               lambda: robot.read_pose()[:3, :3].detach().numpy() @ sensor.true_force(),
                               cloth_thickness=self.cover.thickness if self.cover.dim == 2 else 0.0,
                               clock=lambda: physics.time, cover=cover_rays, pinch=2 * self.cover.radius + 1e-3)

    def penalty(self):
        return self.range_penalty()

    def crop_box(self) -> np.ndarray:
        return self.range

    def true_surface_samples(self, spacing: float) -> np.ndarray:
        """`(n, 3)` samples of the body's whole surface, about one per ``spacing``^2 [m]."""
        return self.body.surface_samples(spacing)

    @property
    def inner(self):
        """The inner surface as a ``trimesh.Trimesh``: a mesh body's mesh, or marching cubes of the primitives' exact
        union SDF at 5 mm (for figures and exports; the metrics use the exact SDF)."""
        if isinstance(self.body, MeshBody):
            return self.body.mesh
        if getattr(self, "_inner_mesh", None) is None:
            from ..shapes3d import mesh_from_sdf

            # the grid is offset by an irrational fraction of a cell: box faces lying exactly on grid planes make
            # marching cubes emit degenerate triangles that leave the mesh open
            box = self.range + np.array([[-0.3], [0.3]]) + 0.005 * (math.sqrt(2) - 1)
            self._inner_mesh = mesh_from_sdf(self.body.sdf, box, 0.005)
        return self._inner_mesh

    def inner_outer_hausdorff(self, spacing: float = 0.003) -> float:
        """Hausdorff distance [m] between the inner surface and the settled cover (in the exploration range)."""
        from ...geometry.metrics import hausdorff_distance

        verts = self.cover_vertices()
        return hausdorff_distance(self.inner_samples_in_range(spacing), verts[self.in_range(verts)])

    def measure(self, model, contacts, resolution: float | None = None) -> Measurement:
        from ..ruler import METRICS_GRID, estimate_metrics_3d

        return estimate_metrics_3d(model, self, METRICS_GRID if resolution is None else resolution, contacts=contacts)

    def fingerprint(self) -> str:
        return geometry_hash(
            *self.body.fingerprint(),
            self.cover.vertices,
            self.cover.elements,
            self.start,
            self.direction,
            self.range,
            [self.seed, self.sensor_noise, self.timestep, self.settle_time],
            # a scene without a camera error hashes as before there were any
            *self.camera_error.fingerprint(),
        )

    def snapshot(self, hw: Hardware) -> dict[str, np.ndarray]:
        return {**{f"robot_{k}": v for k, v in hw.robot.get_state().items()},
                **{f"sensor_{k}": v for k, v in hw.sensor.get_state().items()}}

    def restore(self, hw: Hardware, state: dict[str, np.ndarray]) -> None:
        hw.robot.set_state({k[6:]: v for k, v in state.items() if k.startswith("robot_")})
        hw.sensor.set_state({k[7:]: v for k, v in state.items() if k.startswith("sensor_")})

    def perturbed(self, seed: int) -> "MujocoScene":
        """The same object and cover with a seeded perturbation (seed 0: unchanged): the start moved within a 2 cm
        disc across the approach, the approach turned by up to 10 deg, and the sensor and camera noise from
        ``seed``."""
        if seed == 0:
            return self
        # redraw an approach that misses or only grazes the body (as the force-field world)
        for start, direction in perturbed_approaches(self.start, self.direction, np.random.default_rng([seed, 5])):
            if self.approach_depth(start, direction) >= self.MIN_APPROACH_DEPTH:
                break
        else:
            raise ValueError(f"seed {seed}: no perturbed approach passes {self.MIN_APPROACH_DEPTH * 1e3:.0f} mm into "
                             "the body")
        return self._copy(start, direction, seed)

    #: A perturbed approach must pass at least this deep [m] into the body (its centre line): one that only grazes an
    #: edge slides off it, or past it out of the workspace.
    MIN_APPROACH_DEPTH = 0.003

    def approach_depth(self, start, direction, reach: float = 1.0) -> float:
        """How deep [m] the line from ``start`` `(3,)` along ``direction`` `(3,)` passes into the body on its first
        passage (0 if it misses within ``reach`` [m]), from the body's exact distance every millimetre."""
        _, sdf = self._along(start, direction, reach)
        inside = np.flatnonzero(sdf < 0)
        if len(inside) == 0:
            return 0.0
        first = inside[0]
        out = np.flatnonzero(sdf[first:] >= 0)
        end = first + (out[0] if len(out) else len(sdf) - first)
        return float(-sdf[first:end].min())

    def real_time_factor(self, seconds: float = 1.0) -> float:
        """Simulated seconds per wall-clock second of the settled scene with the arm holding still."""
        import time

        from .hardware import MujocoPhysics

        physics = MujocoPhysics(self.model)
        physics.set_state(self.settled)
        n = max(1, int(round(seconds / self.timestep)))
        t0 = time.perf_counter()
        physics.step(n)
        return n * self.timestep / (time.perf_counter() - t0)

    def true_distance(self, points: np.ndarray) -> np.ndarray:
        """`(n,)` exact signed distance of `(n, 3)` points from the inner object [m] (negative inside)."""
        return self.body.sdf(np.asarray(points, dtype=np.float64).reshape(-1, 3))

    def contact_truth(self, hw, contact):
        """The contact's distance from the body, and whether the fingertip presses on the body at this moment: its
        surface lies within one pinched cover layer (two element radii) plus 1 mm of the body. False: the cover
        alone carries the force (a cloth stretched like a trampoline, a fold, a bunch of fabric)."""
        tip = hw.robot.physics.data.geom_xpos[self._tip_geom].copy()
        gap = float(self.true_distance(tip[None])[0]) - self.tip_radius
        on = gap <= 2 * self.cover.radius + 0.001
        return ContactTruth(float(self.true_distance(np.asarray(contact)[None])[0]), bool(on))

    def truth(self) -> dict:
        """The true inner surface (:attr:`inner`) [m]; the cover settles at run time, so its outer shape is what the
        camera saw (None here)."""
        return {"inner": self.inner, "outer": None}

    def __repr__(self) -> str:
        return (f"MujocoScene({self.name!r}, {self.body.describe()}, {self.cover.kind} cover with "
                f"{len(self.cover.vertices)} vertices)")
