"""The world behind the exploration loop: a robot, a force sensor and a point-cloud source, one interface each.

The loop plans, moves, senses and records through these and never asks which world it runs in. Every world -- the 2-D
polygon world, the 3-D force-field world, MuJoCo, a real UR5 with an OptoForce and a camera -- is a :class:`World` that
supplies

* :meth:`World.hardware`: a :class:`Hardware` with the robot (Cartesian moves behind a safety gate), the force
  sensor, the point-cloud source, and the contact controller that turns a planned step into force-guarded motion
  (:class:`torch_gpioius.exploration.contact.ContactController` on a robot arm; a geometric one in the 2-D world);
* where to start: ``start``, ``direction`` (the approach), and the exploration range (``bounds``, eq. 25);
* :attr:`World.defaults`: the world's own settings (alpha, stop rules, the estimator's settings);
* :meth:`World.measure`: the ground-truth metrics (eq. 23-24) where the truth is known;
* :meth:`World.fingerprint`, :meth:`World.snapshot` / :meth:`World.restore`: what logs and resume need;
* :meth:`World.perturbed`: the same world with a seeded perturbation (start, approach, sensor and camera noise)
  for studies over seeds.
"""

from __future__ import annotations

import abc
import dataclasses
import hashlib
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.validation import as_bounds
from .contact import ContactController
from ..models.estimator import EstimatorSettings, EstimatorView
from .protocols import Toucher
from .registry import register_world
from .stopping import StopRule, TravelBudget

__all__ = ["World", "Hardware", "Toucher", "ExplorationDefaults", "Measurement", "ContactTruth", "RobotWorld",
           "geometry_hash", "perturbed_approaches"]


@dataclass
class Hardware:
    """One world's hardware: the three interfaces of the loop, and the controller built from robot and sensor.

    Attributes:
        robot: Cartesian moves behind a safety gate (``move_cartesian(dx, speed)``, ``tool_position()``,
            ``stop()``, a ``time`` clock) -- a :class:`kinematics.RobotBackend` on an arm.
        sensor: a :class:`torch_gpioius.sensors.ForceSensor`.
        camera: a :class:`torch_gpioius.sensors.PointCloudSource`.
        controller: ``approach(direction, max_travel)`` and ``slide(step, normal)`` returning
            :class:`torch_gpioius.exploration.contact.ContactResult`.
        tactile: a tactile pad at the fingertip (:class:`torch_gpioius.sensors.tactile.TactileSensor`) or None;
            ``touch="patch"`` reads it at each contact.
    """

    robot: Any
    sensor: Any
    camera: Any
    controller: Toucher
    tactile: Any = None

    def robot_time(self) -> float:
        """The robot's clock [s] (its ``time``: every backend of the project keeps one), NaN for a robot that keeps
        none: what a step's record says of the motion's time."""
        return float(getattr(self.robot, "time", math.nan))

    def approach_limit(self) -> float | None:
        """The longest approach the controller accepts [m] (its ``max_approach``), or None: no limit of its own."""
        limit = getattr(self.controller, "max_approach", None)
        return None if limit is None else float(limit)


@dataclass(frozen=True)
class ExplorationDefaults(EstimatorView):
    """A world's own exploration settings; every one can be overridden in :func:`torch_gpioius.explore`.

    The estimator's part (kernel, sigma^2, labels, what is learned) is one
    :class:`~torch_gpioius.models.estimator.EstimatorSettings`, defined in the model layer: the world only suggests
    which settings its objects run with (the robot study's objects E-H the paper's, a user's mesh the library's
    default), and ``explore(settings=...)`` gives any other. ``kernel``, ``lengthscale``, ``noise``, ``policy`` and
    ``learn`` read it (:class:`~torch_gpioius.models.estimator.EstimatorView`); :meth:`with_estimator` and
    :meth:`estimator_changed` change it.

    Attributes:
        step: alpha, the planned step [m].
        max_steps: cap on planning steps.
        stop: the world's stop rules (:mod:`torch_gpioius.exploration.stopping`).
        metrics_every: ground-truth metrics every k steps (and always at the last).
        approach_travel: the approach gives up after this distance [m].
        estimator: the estimator's settings (default: the paper's 2-D ones).
    """

    step: float = 0.01
    max_steps: int = 400
    stop: tuple[StopRule, ...] = ()
    metrics_every: int = 1
    approach_travel: float = 2.0
    estimator: EstimatorSettings = field(default_factory=EstimatorSettings.paper_2d)

    def __post_init__(self) -> None:
        if not isinstance(self.estimator, EstimatorSettings):
            raise ValueError(f"estimator: expected EstimatorSettings, got {type(self.estimator).__name__}")
        object.__setattr__(self, "stop", tuple(self.stop))

    def with_estimator(self, estimator: EstimatorSettings) -> "ExplorationDefaults":
        """These defaults with another estimator's settings."""
        if not isinstance(estimator, EstimatorSettings):
            raise ValueError(f"settings: expected EstimatorSettings, got {type(estimator).__name__}")
        return dataclasses.replace(self, estimator=estimator)

    def estimator_changed(self, **changes) -> "ExplorationDefaults":
        """These defaults with the estimator's settings changed (:meth:`EstimatorSettings.replace`'s fields; a
        ``labels`` dict changes single labels), or themselves when nothing is given."""
        return self if not changes else self.with_estimator(self.estimator.replace(**changes))


@dataclass
class Measurement:
    """Ground-truth metrics of an estimate (NaN where the truth is unknown, e.g. on a real robot).

    Attributes:
        hausdorff: eq. (24) between the whole zero set {mu_in = 0} and the true inner surface [m].
        hausdorff_touched: the same for the touched pieces only
            (:func:`torch_gpioius.geometry.surfaces.touched_pieces`).
        uncertainty: eq. (23), relative to the prior variance.
        centre: centroid of the estimated inner region {mu_in < 0} (2-D; None otherwise or if empty).
        surface: the estimated surface (2-D: list of polylines; 3-D: a ``trimesh.Trimesh`` in the range, or None).
        estimate: whether the estimate has a surface to judge (2-D: a closed curve; 3-D: surface inside the range);
            None where the world did not look (no known truth).
        shape: the field's shape metrics (:func:`torch_gpioius.geometry.metrics.surface_agreement`: Chamfer, F-scores,
            signed bias, Hausdorff over the observed surface, unseen share), ``{}`` where not computed.
    """

    hausdorff: float = math.nan
    hausdorff_touched: float = math.nan
    uncertainty: float = math.nan
    centre: np.ndarray | None = None
    surface: Any = None
    estimate: bool | None = None
    shape: dict = field(default_factory=dict)


@dataclass
class ContactTruth:
    """Where a contact lies relative to the true body, in a world that knows it.

    Attributes:
        distance: signed distance of the contact point from the true inner surface [m] (negative inside).
        on_body: whether the fingertip touched the body itself at that moment (False: it pressed only on the cover,
            e.g. cloth carrying the force); None where the world cannot tell.
    """

    distance: float = math.nan
    on_body: bool | None = None


def perturbed_approaches(start, direction, rng, radius: float = 0.02, max_angle: float = 10.0,
                         tries: int = 100):
    """Seeded candidate approaches for ``World.perturbed`` in 3-D: ``(start (3,), direction (3,))`` pairs, the start
    moved uniformly within a disc of ``radius`` [m] across the approach, the direction turned by up to ``max_angle``
    [deg] (uniform on the cap), ``tries`` of them from ``rng`` (``numpy.random.Generator``). A world takes the first
    one it accepts (one that reaches its body), so a seed always gives the same approach."""
    start, d = np.asarray(start, dtype=np.float64), np.asarray(direction, dtype=np.float64)
    u = np.cross(d, [0.0, 0.0, 1.0] if abs(d[2]) < 0.9 else [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    for _ in range(tries):
        r, phi = radius * math.sqrt(rng.uniform()), rng.uniform(0, 2 * math.pi)
        s = start + r * (math.cos(phi) * u + math.sin(phi) * v)
        cos_t = 1 - rng.uniform() * (1 - math.cos(math.radians(max_angle)))
        sin_t, psi = math.sqrt(max(0.0, 1 - cos_t * cos_t)), rng.uniform(0, 2 * math.pi)
        yield s, cos_t * d + sin_t * (math.cos(psi) * u + math.sin(psi) * v)


def geometry_hash(*arrays) -> str:
    """SHA-256 (first 16 hex digits) of numeric arrays: a world's geometry fingerprint for logs and resume."""
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(np.asarray(a, dtype=np.float64))
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


class World(abc.ABC):
    """Base class of the worlds the exploration loop runs in (see the module docstring).

    Subclasses set ``name``, ``dim``, ``start`` `(d,)` [m], ``direction`` `(d,)` (unit) and implement
    :meth:`hardware`, :meth:`penalty`, :attr:`defaults`; worlds with a known truth implement :meth:`measure`.
    A world registers itself by name (:func:`torch_gpioius.exploration.registry.register_world`), which sets
    :attr:`kind`.
    """

    #: The registry name of the world's kind ("planar", "forcefield", "mujoco", "robot", or a user's).
    kind: str = ""
    #: What measures this world's estimates (:meth:`measure`): records and study files carry it, and a study's run
    #: measured by another ruler is done again rather than mixed with the others; None where nothing is measured.
    ruler: str | None = None
    name: str = ""
    dim: int = 3
    #: The scene file the world was built from, ``{"path": absolute path, "hash": its content's digest}``
    #: (:func:`torch_gpioius.sim.scenefile.scene_fingerprint`), or None: a log records it, so that a viewer or an
    #: export can rebuild the true shapes of a user's scene while the file is unchanged.
    scene_file: dict | None = None
    start: np.ndarray
    direction: np.ndarray

    @property
    @abc.abstractmethod
    def defaults(self) -> ExplorationDefaults:
        """This world's exploration settings."""

    @abc.abstractmethod
    def hardware(self) -> Hardware:
        """A fresh :class:`Hardware` (robot at the start pose, sensor, camera, controller)."""

    def penalty(self):
        """C(x) of eq. (19)/(25) for this world (default: zero)."""
        from .planning import ZeroPenalty

        return ZeroPenalty()

    def crop_box(self) -> np.ndarray | None:
        """`(2, d)` box [min; max] the camera's cloud is cropped to (None: no crop); see ``policy.crop_margin``."""
        return None

    def measure(self, model, contacts: np.ndarray, resolution: float | None = None) -> Measurement:
        """Ground-truth metrics of ``model``'s inner estimate; a world without a known truth returns NaNs."""
        return Measurement()

    def true_distance(self, points: np.ndarray) -> np.ndarray | None:
        """`(n,)` signed distance of `(n, d)` points from the true inner surface [m] (negative inside); None where the
        world does not know the truth."""
        return None

    def contact_truth(self, hw: Hardware, contact: np.ndarray) -> ContactTruth | None:
        """Where ``contact`` `(d,)` [m], just reached with ``hw``, lies relative to the true body; None where the
        world does not know (a real robot). The default knows the distance (:meth:`true_distance`) but not whether
        the body itself was touched."""
        d = self.true_distance(np.asarray(contact, dtype=np.float64)[None])
        return None if d is None else ContactTruth(float(d[0]), None)

    def fingerprint(self) -> str:
        """A digest of everything that defines this world's geometry (resume refuses a log from another)."""
        return geometry_hash(self.start, self.direction)

    def snapshot(self, hw: Hardware) -> dict[str, np.ndarray]:
        """The hardware state needed to resume after a step (e.g. the robot's joints); numeric arrays only."""
        return {}

    def restore(self, hw: Hardware, state: dict[str, np.ndarray]) -> None:
        """Put ``hw`` back into a state from :meth:`snapshot`."""
        if state:
            raise ValueError(f"{type(self).__name__}: cannot restore a hardware state on resume")

    def perturbed(self, seed: int) -> "World":
        """This world with a seeded perturbation (seed 0 is the world itself); see the study module."""
        if seed == 0:
            return self
        raise NotImplementedError(f"{type(self).__name__} does not support seeded perturbations")

    def describe(self) -> dict:
        """JSON-able description for log headers."""
        out = {"world": self.kind or type(self).__name__, "scene": self.name, "dim": self.dim,
               "scene_fingerprint": self.fingerprint()}
        if self.scene_file:
            out["scene_file"] = dict(self.scene_file)
        return out

    def truth(self) -> dict | None:
        """The true shapes for viewers and exports: 2-D ``{"inner": [(m, 2)], "outer": [(m, 2)]}`` closed polylines,
        3-D ``{"inner": Trimesh, "outer": Trimesh | None}`` [m]; None where the world does not know them."""
        return None

    @property
    def object_extent(self) -> float | None:
        """The largest extent [m] of the body, where the world knows it (its ``inner`` mesh): what the estimator
        settings' voxel and length rules size the camera's voxels and the kernel to; None elsewhere."""
        inner = getattr(self, "inner", None)
        extents = getattr(inner, "extents", None)
        return None if extents is None else float(np.max(extents))


class RobotWorld(World):
    """A real robot: a UR5 (``kinematics.RTDEUR5``), a force sensor (``OptoForceDAQ``) and a point-cloud source.

    The hardware objects are given; the loop drives them exactly as it drives the simulated ones. A reference
    world with the true geometry (e.g. a ``Scene3D`` built from a scan of the object) gives the metrics; without
    one the metrics are the uncertainty only.

    Args:
        robot: a connected :class:`kinematics.RobotBackend` whose fingertip is at the start pose, pointing along
            ``direction``, with a :class:`kinematics.SafetyGate` sized for the task.
        sensor: a :class:`torch_gpioius.sensors.ForceSensor` (tared, free of contact).
        camera: a :class:`torch_gpioius.sensors.PointCloudSource` in the base frame.
        direction: `(3,)` approach direction (base frame).
        bounds: `(2, 3)` exploration range `[min corner; max corner]` [m] (the eq. 25 penalty keeps the planner in it).
        name: label for records.
        reference: an optional world with the true geometry (used for :meth:`measure` only).
        config: :class:`torch_gpioius.exploration.contact.ContactConfig` for the controller.
        defaults: overrides of the robot study's defaults (theta 0.15, sigma^2 0.08, 1.5 m of travel).
    """

    dim = 3

    def __init__(self, robot, sensor, camera, direction, bounds, *, name: str = "robot", reference: World | None =
                 None, config=None, defaults: ExplorationDefaults | None = None) -> None:
        self.robot, self.sensor, self.camera = robot, sensor, camera
        self.start = np.asarray(robot.tool_position().detach().cpu().numpy(), dtype=np.float64)
        d = np.asarray(direction, dtype=np.float64).reshape(-1)
        if d.shape != (3,) or not np.isfinite(d).all() or np.linalg.norm(d) == 0:
            raise ValueError("direction: must be a finite non-zero 3-vector")
        self.direction = d / np.linalg.norm(d)
        self.range = as_bounds(bounds, 3)
        self.name, self.reference = name, reference
        self.controller = ContactController(robot, sensor, config)
        self._defaults = defaults or ExplorationDefaults(stop=(TravelBudget(1.5),), metrics_every=5,
                                                         estimator=EstimatorSettings.paper())

    @property
    def defaults(self) -> ExplorationDefaults:
        return self._defaults

    def hardware(self) -> Hardware:
        return Hardware(self.robot, self.sensor, self.camera, self.controller)

    def penalty(self):
        from .planning import RangePenalty

        return RangePenalty(self.range[0], self.range[1], beta=100.0)

    def crop_box(self):
        return self.range

    @property
    def object_extent(self) -> float:
        """The largest extent [m] of the reference world's body where one is given, else of the exploration range
        (the box the object is known to lie in, as a bag import sizes the settings to its crop box): what the
        estimator settings' voxel and length rules size to."""
        known = None if self.reference is None else self.reference.object_extent
        return float(np.max(self.range[1] - self.range[0])) if known is None else known

    def measure(self, model, contacts, resolution=None):
        if self.reference is not None:
            return self.reference.measure(model, contacts, resolution)
        return Measurement()

    def contact_truth(self, hw, contact):
        """The contact's distance from the reference world's true body (whether the real fingertip touched it the
        robot cannot tell)."""
        d = None if self.reference is None else self.reference.true_distance(np.asarray(contact)[None])
        return None if d is None else ContactTruth(float(d[0]), None)

    def fingerprint(self) -> str:
        return geometry_hash(self.direction, self.range)


register_world("robot", RobotWorld, simulated=False,
               description="a real UR5 with a fingertip force sensor and a depth camera")
