"""The 2-D world of the paper's simulation (Sec. V): a point-mass toucher, a rigid inner polygon and a soft outer
polygon it passes through, seen all round by a camera. Geometry by shapely.

The world supplies the loop's three interfaces geometrically (the paper's toucher is "a point mass with a
tactile sensor"): a :class:`PlanarRobot` whose Cartesian moves pass a :class:`PlanarGate`, a
:class:`PlanarForceSensor` reading contact with the rigid inner polygon, and a :class:`PlanarCamera` that sees
the outer boundary. The contact controller :class:`PlanarContact` settles the compliant fingertip onto the
nearest point of the inner surface after each planned step (docs/method-notes.md, section 3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from shapely.geometry import LineString, Point, Polygon

from ..exploration.contact import ContactResult
from ..exploration.observations import free_space_along
from ..models.estimator import EstimatorSettings
from ..exploration.stopping import OnceAround
from ..exploration.registry import register_world
from ..exploration.world import ContactTruth, ExplorationDefaults, Hardware, Measurement, World, geometry_hash
from ..geometry.metrics import hausdorff_distance
from ..sensors.base import ForceReading, ForceSensor
from ..sensors.pointcloud import PointCloud, PointCloudSource
from ..core.validation import as_bounds

__all__ = ["Scene2D", "paper_objects_2d", "rectangle", "PlanarRobot", "PlanarGate", "PlanarForceSensor",
           "PlanarCamera", "PlanarView", "PlanarContact"]


def rectangle(x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    """`(4, 2)` counter-clockwise vertices of an axis-aligned rectangle [m]."""
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)


def _polygon(vertices, name: str) -> Polygon:
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 2 or len(v) < 3 or not np.isfinite(v).all():
        raise ValueError(f"{name}: expected (k >= 3, 2) finite vertices [m], got shape {v.shape}")
    poly = Polygon(v)
    if not poly.is_valid or poly.area <= 0:
        raise ValueError(f"{name}: vertices do not form a simple polygon with positive area")
    return poly


# ---------------------------------------------------------------------------------------------- hardware
class PlanarGate:
    """The 2-D world's safety gate: a workspace box and the longest single move; refuses, never clips.

    Args:
        bounds: `(2, 2)` box `[min corner; max corner]` [m].
        max_step: longest single Cartesian move [m].
    """

    def __init__(self, bounds, max_step: float = 0.5) -> None:
        self.bounds = as_bounds(bounds, 2)
        if isinstance(max_step, bool) or not (isinstance(max_step, (int, float)) and math.isfinite(max_step)
                                              and 0 < max_step <= 2.0):
            raise ValueError(f"max_step: must be in (0, 2] m, got {max_step!r}")
        self.max_step = float(max_step)

    def check(self, p_from: np.ndarray, dx: np.ndarray) -> None:
        from kinematics import SafetyViolation

        if dx.shape != (2,) or not np.isfinite(dx).all():
            raise SafetyViolation(f"a planar step is 2 finite numbers [m], got {dx}")
        if float(np.linalg.norm(dx)) > self.max_step:
            raise SafetyViolation(f"planar step of {np.linalg.norm(dx) * 1e3:.1f} mm exceeds the "
                                  f"{self.max_step * 1e3:.1f} mm limit")
        end = p_from + dx       # the box is convex: a straight move stays inside iff its end does
        if not ((end >= self.bounds[0]) & (end <= self.bounds[1])).all():
            raise SafetyViolation(f"the fingertip would leave the workspace box at {end.round(4).tolist()} m")


class PlanarRobot:
    """A point-mass fingertip in the plane, moved by Cartesian steps behind a :class:`PlanarGate`.

    Args:
        position: `(2,)` start [m].
        gate: the gate every move passes.
        speed: fingertip speed for the clock [m/s].
    """

    def __init__(self, position, gate: PlanarGate, speed: float = 0.02) -> None:
        self._p = np.asarray(position, dtype=np.float64).reshape(2).copy()
        self.gate, self.speed, self.time = gate, float(speed), 0.0
        self.stopped = False

    def tool_position(self) -> torch.Tensor:
        """`(2,)` fingertip position [m]."""
        return torch.as_tensor(self._p.copy())

    def read_pose(self) -> torch.Tensor:
        """`(3, 3)` homogeneous planar pose ``T_world_tool`` (the tool frame is not rotated)."""
        T = torch.eye(3, dtype=torch.float64)
        T[:2, 2] = torch.as_tensor(self._p)
        return T

    def move_cartesian(self, dx, speed: float | None = None) -> torch.Tensor:
        """Move by ``dx`` `(2,)` [m]; refused by the gate (``SafetyViolation``) before anything moves."""
        d = np.asarray(dx, dtype=np.float64).reshape(-1)
        self.move_to(self._p + d, speed)
        return torch.as_tensor(d)

    def move_to(self, p, speed: float | None = None) -> None:
        """Move straight to ``p`` `(2,)` [m] (the gate checks the displacement); the point mass ends exactly there."""
        p = np.asarray(p, dtype=np.float64).reshape(-1)
        d = p - self._p
        self.gate.check(self._p, d)
        self._p = p.copy()
        self.time += float(np.linalg.norm(d)) / (speed or self.speed)

    def set_position(self, p) -> None:
        """Place the fingertip without moving it (resume only)."""
        self._p = np.asarray(p, dtype=np.float64).reshape(2).copy()

    def stop(self) -> None:
        self.stopped = True


class PlanarForceSensor(ForceSensor):
    """Contact with the rigid inner polygon: ``contact_force`` [N] along the outward normal when the fingertip is on
    or inside the inner shape, zero outside (the soft cover is too soft to register, as in the paper's 2-D study).

    Args:
        scene: the :class:`Scene2D`.
        robot: the :class:`PlanarRobot` whose fingertip it reads.
        contact_force: the force of a settled compliant fingertip [N] (between the 1 N contact and 5 N retreat
            thresholds of Sec. VI-A-3).
        tolerance: distance to the boundary that counts as touching [m].
    """

    def __init__(self, scene: "Scene2D", robot: PlanarRobot, contact_force: float = 2.5, tolerance: float = 1e-9,
                 cover_stiffness: float = 1.0):
        self.scene, self.robot = scene, robot
        self.contact_force, self.tolerance = float(contact_force), float(tolerance)
        self.cover_stiffness = float(cover_stiffness)
        self._counter = 0

    def force_at(self, p: np.ndarray) -> np.ndarray:
        """`(2,)` force at a fingertip position [N]: the settled contact force on the inner shape, else the soft
        cover's push (``cover_stiffness`` times the depth inside the outer shape, 1 N/m: below 0.4 N in the paper's
        objects, far below the 1 N contact threshold), along the outer boundary's outward normal."""
        boundary = self.scene.inner.exterior
        q = np.asarray(boundary.interpolate(boundary.project(Point(p))).coords[0])
        inside = self.scene.inner.contains(Point(p))
        if inside or np.linalg.norm(p - q) <= self.tolerance:
            return self.contact_force * self.scene.outward_normal(q)
        if self.cover_stiffness > 0 and self.scene.outer.contains(Point(p)):
            ring = self.scene.outer.exterior
            o = np.asarray(ring.interpolate(ring.project(Point(p))).coords[0])
            return self.cover_stiffness * float(np.linalg.norm(o - p)) * self.scene.outward_normal(o, which="outer")
        return np.zeros(2)

    def read(self) -> ForceReading:
        self._counter = (self._counter + 1) & 0xFFFF
        f = self.force_at(self.robot.tool_position().numpy())
        return ForceReading(torch.as_tensor(f), 0, self._counter, float(self.robot.time))

    def tare(self) -> None:
        pass


@dataclass
class PlanarView(PointCloud):
    """What the 2-D camera sees: the outer boundary every ``spacing`` (no depth rays in the paper's 2-D world: the
    outer shape is seen all round). Its free space is the curve ``offset`` outside the outer polygon."""

    polygon: Polygon | None = None
    spacing: float = 0.02

    @property
    def sees_free_space(self) -> bool:
        return self.polygon is not None

    def free_space(self, offset: float) -> np.ndarray:
        ring = self.polygon.buffer(offset, join_style="round").exterior
        n = max(3, int(math.ceil(ring.length / self.spacing)))
        return np.array([ring.interpolate(i * ring.length / n).coords[0] for i in range(n)])

    def with_normals(self, voxel: float | None = None) -> None:
        """None: a 2-D view has no fixed lines to place inside points on; :meth:`behind` samples the curve at each
        depth afresh, from the outline it knows."""
        return None

    def behind(self, depth: float, voxel: float | None = None) -> np.ndarray:
        """`(k, 2)` points on the curve ``depth`` [m] inside the outer polygon, every ``spacing`` (none where the
        polygon is thinner than twice ``depth``); ``voxel`` must be None (a 2-D view is not voxel-averaged)."""
        if voxel:
            raise ValueError("a 2-D view is sampled at its spacing; it is not voxel-averaged (policy.voxel = None)")
        inner = self.polygon.buffer(-float(depth), join_style="round")
        rings = [g.exterior for g in getattr(inner, "geoms", [inner]) if not g.is_empty]
        pts = [np.array([r.interpolate(i * r.length / n).coords[0] for i in range(n)])
               for r in rings for n in [max(3, int(math.ceil(r.length / self.spacing)))]]
        return np.concatenate(pts) if pts else np.zeros((0, 2))

    def voxel_averaged(self, voxel: float) -> "PlanarView":
        raise ValueError("a 2-D view is sampled at its spacing; it is not voxel-averaged (policy.voxel = None)")


class PlanarCamera(PointCloudSource):
    """The 2-D world's vision: the outer boundary sampled every ``spacing`` [m], with optional Gaussian noise
    ``noise_std`` [m] across it (seeded).

    Args:
        scene: the :class:`Scene2D`.
        spacing: sampling of the boundary [m].
        noise_std: noise along the outward normal of each seen point [m].
        seed: noise seed.
    """

    def __init__(self, scene: "Scene2D", spacing: float = 0.02, noise_std: float = 0.0, seed: int = 0) -> None:
        self.scene, self.spacing, self.noise_std, self.seed = scene, float(spacing), float(noise_std), int(seed)

    def capture(self) -> PlanarView:
        pts = self.scene.sample_boundary("outer", self.spacing)
        if self.noise_std > 0:
            rng = np.random.default_rng(self.seed)
            normals = np.array([self.scene.outward_normal(p, which="outer") for p in pts])
            pts = pts + normals * rng.normal(0.0, self.noise_std, len(pts))[:, None]
        return PlanarView(pts, None, polygon=self.scene.outer, spacing=self.spacing)


class PlanarContact:
    """The 2-D contact controller: moves the point-mass fingertip and settles it onto the rigid inner surface.

    ``approach``: straight along the approach direction to the first point of the inner boundary. ``slide``: the
    planned step, then the compliant settle onto the nearest point of the inner boundary (pressed onto it, or
    pushed back out after a step into a concave part; docs/method-notes.md, section 3). Both are Cartesian moves
    through the gate; the force sensor confirms the contact. Free space is what the fingertip crossed outside the
    inner shape, sampled every ``sensing_step`` [m].
    """

    def __init__(self, scene: "Scene2D", robot: PlanarRobot, sensor: PlanarForceSensor, sensing_step: float = 0.02,
                 contact_force: float = 1.0):
        self.scene, self.robot, self.sensor = scene, robot, sensor
        self.sensing_step, self.contact_force = float(sensing_step), float(contact_force)

    def _result(self, points: list[np.ndarray], free: np.ndarray, travel: float) -> ContactResult:
        force = self.sensor.force_at(points[-1])
        forces = torch.as_tensor(np.array([self.sensor.force_at(p) for p in points]))
        return ContactResult(bool(np.linalg.norm(force) >= self.contact_force), torch.as_tensor(points[-1].copy()),
                             torch.as_tensor(np.asarray(free).reshape(-1, 2)), torch.as_tensor(np.array(points)),
                             forces, float(travel))

    def approach(self, direction, max_travel: float = 2.0) -> ContactResult:
        start = self.robot.tool_position().numpy()
        contact = self.scene.first_contact_from(start, np.asarray(direction, dtype=np.float64))
        if contact is None or np.linalg.norm(contact - start) > max_travel:
            return self._result([start], np.zeros((0, 2)), 0.0)
        self.robot.move_to(contact)
        free = free_space_along(start, contact, self.sensing_step)
        return self._result([start, contact], free, float(np.linalg.norm(contact - start)))

    def lift(self, direction, *, step: float = 0.005, until_force_below: float = 0.1, extra: float = 0.01,
             max_distance: float = 0.2, inside=None) -> ContactResult:
        """Move away along ``direction`` in ``step`` moves until the force drops below ``until_force_below``, then
        ``extra`` further (at most ``max_distance``); see
        :meth:`torch_gpioius.exploration.contact.ContactController.lift`."""
        d = np.asarray(direction, dtype=np.float64).reshape(2)
        d = d / np.linalg.norm(d)
        x = self.robot.tool_position().numpy()
        points, moved, beyond = [x], 0.0, None
        while moved < max_distance - 1e-12:
            if beyond is None and np.linalg.norm(self.sensor.force_at(points[-1])) < until_force_below and not (
                    inside is not None and inside(torch.as_tensor(points[-1]))):
                beyond = moved
            if beyond is not None and moved - beyond >= extra - 1e-12:
                break
            s = min(step, max_distance - moved)
            self.robot.move_to(points[-1] + s * d)
            points.append(points[-1] + s * d)
            moved += s
        free = np.array([p for p in points[1:] if np.linalg.norm(self.sensor.force_at(p)) < self.contact_force])
        res = self._result(points, free.reshape(-1, 2), moved)
        res.in_contact = False
        return res

    def slide(self, step, normal=None) -> ContactResult:
        x = self.robot.tool_position().numpy()
        d = np.asarray(step, dtype=np.float64).reshape(2)
        moved = x + d
        self.robot.move_to(moved)
        settled = self.scene.settle(moved)
        self.robot.move_to(settled)                 # the settle is a move of its own, through the gate
        free = free_space_along(moved, settled, self.sensing_step) if not self.scene.is_inside_inner(moved) else \
            np.zeros((0, 2))
        return self._result([moved, settled], free, float(np.linalg.norm(d) + np.linalg.norm(settled - moved)))


# ---------------------------------------------------------------------------------------------- the world
class Scene2D(World):
    """A covered object in the plane, seen from outside and touched by a point-mass toucher.

    Args:
        inner: `(k, 2)` vertices of the rigid inner polygon [m].
        outer: `(l, 2)` vertices of the soft outer polygon [m] (must contain the inner one).
        start: `(2,)` toucher start position [m], outside the outer polygon.
        direction: `(2,)` approach direction (normalised here).
        name: label for figures and records.
        camera_spacing: the camera sees the outer boundary every this [m].
        camera_noise: Gaussian noise of the seen points across the boundary [m] (seeded; 0 in the paper's study).
        seed: seed of the camera noise.

    Raises:
        ValueError: invalid polygons, an outer that does not contain the inner, a start inside the outer
            shape, or an approach ray that misses the inner shape.
    """

    dim = 2

    def __init__(self, inner, outer, start, direction, name: str = "", camera_spacing: float = 0.02,
                 camera_noise: float = 0.0, seed: int = 0):
        self.inner = _polygon(inner, "inner")
        self.outer = _polygon(outer, "outer")
        if not self.outer.buffer(1e-9).contains(self.inner):
            raise ValueError("outer: must contain the inner polygon (a cover around the object)")
        self.start = np.asarray(start, dtype=np.float64).reshape(-1)
        if self.start.shape != (2,) or not np.isfinite(self.start).all():
            raise ValueError(f"start: expected a finite (2,) position [m], got {start!r}")
        d = np.asarray(direction, dtype=np.float64).reshape(-1)
        if d.shape != (2,) or not np.isfinite(d).all() or np.linalg.norm(d) == 0:
            raise ValueError("direction: must be a finite non-zero 2-vector")
        self.direction = d / np.linalg.norm(d)
        if self.outer.contains(Point(self.start)):
            raise ValueError("start: must lie outside the outer polygon")
        self.name = name
        self.camera_spacing, self.camera_noise, self.seed = float(camera_spacing), float(camera_noise), int(seed)
        self.first_contact()  # raises if the approach misses

    # ------------------------------------------------------------------ the World interface
    @property
    def defaults(self) -> ExplorationDefaults:
        """The paper's 2-D settings: theta 0.1, sigma^2 0.006, alpha 1 cm, C = 0, once around (or 400 steps)."""
        return ExplorationDefaults(step=0.01, max_steps=400, stop=(OnceAround(),), metrics_every=1,
                                   approach_travel=10.0, estimator=EstimatorSettings.paper_2d())

    def hardware(self) -> Hardware:
        gate = PlanarGate(self.bounds(0.5), max_step=1.0)
        robot = PlanarRobot(self.start, gate)
        sensor = PlanarForceSensor(self, robot)
        camera = PlanarCamera(self, self.camera_spacing, self.camera_noise, self.seed)
        return Hardware(robot, sensor, camera, PlanarContact(self, robot, sensor))

    def measure(self, model, contacts, resolution: float | None = None) -> Measurement:
        """Hausdorff (eq. 24; whole zero set and touched pieces), uncertainty (eq. 23) and the centroid of the
        estimated region {mu_in < 0}, on a grid of ``resolution`` (default 1 cm) over :meth:`bounds` (10 cm)."""
        from ..geometry.metrics import curve_shape_metrics, uncertainty_measure
        from ..geometry.surfaces import closed_curves, evaluate_grid, touched_pieces, zero_level_curves

        res = 0.01 if resolution is None else resolution
        bounds = self.bounds(0.1)
        field_ = evaluate_grid(model, bounds, res, 0, variance=False)
        curves = zero_level_curves(model, bounds, res, 0, field=field_)
        unc = uncertainty_measure(model, curves, 0) if curves else math.nan
        inside = field_.mean < 0
        centre = None
        if inside.any():
            gx, gy = np.meshgrid(*field_.axes, indexing="ij")
            centre = np.array([gx[inside].mean(), gy[inside].mean()])
        closed = closed_curves(curves)
        h = hausdorff_distance(closed, [self.inner_boundary], spacing=2e-3) if closed else math.nan
        touched = closed_curves(touched_pieces(curves, contacts)) if len(contacts) else []
        ht = hausdorff_distance(touched, [self.inner_boundary], spacing=2e-3) if touched else math.nan
        shape = curve_shape_metrics(model, closed, [self.inner_boundary]) if closed else {}
        return Measurement(h, ht, unc, centre, curves, estimate=bool(closed), shape=shape)

    def fingerprint(self) -> str:
        return geometry_hash(self.inner_boundary, self.outer_boundary, self.start, self.direction,
                             [self.camera_spacing, self.camera_noise, self.seed])

    def snapshot(self, hw: Hardware) -> dict[str, np.ndarray]:
        return {"position": hw.robot.tool_position().numpy(), "clock": np.array([hw.robot.time])}

    def restore(self, hw: Hardware, state: dict[str, np.ndarray]) -> None:
        hw.robot.set_position(state["position"])
        hw.robot.time = float(np.asarray(state["clock"]).reshape(-1)[0])

    def perturbed(self, seed: int) -> "Scene2D":
        """The same objects with a seeded perturbation (seed 0: unchanged): the start moved uniformly within a
        2 cm disc across the approach (along its perpendicular, within +-2 cm, keeping the first contact on the
        object), the approach direction turned by up to +-10 deg, and camera noise of 1 mm."""
        if seed == 0:
            return self
        rng = np.random.default_rng([seed, 2])
        for _ in range(100):
            shift = rng.uniform(-0.02, 0.02)
            angle = math.radians(rng.uniform(-10.0, 10.0))
            c, s = math.cos(angle), math.sin(angle)
            d = np.array([c * self.direction[0] - s * self.direction[1], s * self.direction[0] + c * self.direction[1]])
            start = self.start + shift * np.array([-self.direction[1], self.direction[0]])
            try:
                return Scene2D(np.asarray(self.inner.exterior.coords)[:-1], np.asarray(self.outer.exterior.coords)[:-1],
                               start, d, name=self.name, camera_spacing=self.camera_spacing, camera_noise=0.001,
                               seed=seed)
            except ValueError:   # the perturbed approach missed the object: draw again
                continue
        raise ValueError(f"seed {seed}: no perturbed approach hits the object")

    # ------------------------------------------------------------------ geometry
    @property
    def inner_boundary(self) -> np.ndarray:
        """`(k + 1, 2)` closed polyline of the inner boundary [m]."""
        return np.asarray(self.inner.exterior.coords)

    @property
    def outer_boundary(self) -> np.ndarray:
        """`(l + 1, 2)` closed polyline of the outer boundary [m]."""
        return np.asarray(self.outer.exterior.coords)

    def bounds(self, margin: float = 0.1) -> np.ndarray:
        """`(2, 2)` box [[x_min, y_min], [x_max, y_max]] of the outer shape and the start, plus ``margin`` [m]."""
        x0, y0, x1, y1 = self.outer.bounds
        x0, x1 = min(x0, self.start[0]), max(x1, self.start[0])
        y0, y1 = min(y0, self.start[1]), max(y1, self.start[1])
        return np.array([[x0 - margin, y0 - margin], [x1 + margin, y1 + margin]])

    def inner_outer_hausdorff(self) -> float:
        """Hausdorff distance between the inner and outer boundaries (Table I) [m]."""
        return hausdorff_distance([self.inner_boundary], [self.outer_boundary], spacing=2e-4)

    def first_contact_from(self, start: np.ndarray, direction: np.ndarray) -> np.ndarray | None:
        """`(2,)` first point of the inner boundary hit from ``start`` along ``direction``, or None [m]."""
        far = start + direction / np.linalg.norm(direction) * 10.0 * (1.0 + np.abs(start).max())
        hit = LineString([start, far]).intersection(self.inner.exterior)
        points = [np.asarray(c) for g in getattr(hit, "geoms", [hit]) if not g.is_empty for c in g.coords]
        if not points:
            return None
        return min(points, key=lambda p: float(np.linalg.norm(p - start)))

    def first_contact(self) -> np.ndarray:
        """`(2,)` first point of the inner boundary hit from ``start`` along ``direction`` [m]."""
        p = self.first_contact_from(self.start, self.direction)
        if p is None:
            raise ValueError("direction: the approach ray from start misses the inner polygon")
        return p

    def settle(self, x: np.ndarray) -> np.ndarray:
        """Where a compliant fingertip at ``x`` comes to rest on the rigid inner surface [m]: the nearest point of
        the inner boundary (pressed onto it, or pushed back out of a concave part; docs/method-notes.md, 3)."""
        boundary = self.inner.exterior
        return np.asarray(boundary.interpolate(boundary.project(Point(np.asarray(x, dtype=np.float64)))).coords[0])

    def outward_normal(self, p: np.ndarray, which: str = "inner") -> np.ndarray:
        """`(2,)` outward unit normal of the inner (or outer) boundary at its point nearest to ``p``."""
        poly = self.inner if which == "inner" else self.outer
        coords = np.asarray(poly.exterior.coords)
        a, b = coords[:-1], coords[1:]
        ab = b - a
        t = np.clip(((p - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-300), 0, 1)
        k = int(np.argmin(np.linalg.norm(a + t[:, None] * ab - p, axis=1)))
        n = np.array([ab[k, 1], -ab[k, 0]])
        n = n / np.linalg.norm(n)
        return n if poly.exterior.is_ccw else -n   # (dy, -dx) of an edge is outward on a counter-clockwise ring

    def is_inside_inner(self, x: np.ndarray) -> bool:
        return bool(self.inner.contains(Point(x)))

    def sample_boundary(self, which: str, spacing: float) -> np.ndarray:
        """Points every ``spacing`` [m] along the inner or outer boundary: `(p, 2)`."""
        ring = (self.inner if which == "inner" else self.outer).exterior
        n = max(3, int(math.ceil(ring.length / spacing)))
        return np.array([ring.interpolate(i * ring.length / n).coords[0] for i in range(n)])

    def sample_offset(self, which: str, offset: float, spacing: float) -> np.ndarray:
        """Points every ``spacing`` along the curve at distance ``offset`` outside a boundary: `(p, 2)` [m]."""
        poly = (self.inner if which == "inner" else self.outer).buffer(offset, join_style="round")
        ring = poly.exterior
        n = max(3, int(math.ceil(ring.length / spacing)))
        return np.array([ring.interpolate(i * ring.length / n).coords[0] for i in range(n)])

    def true_distance(self, points: np.ndarray) -> np.ndarray:
        """`(n,)` signed distance of `(n, 2)` points from the inner polygon's boundary [m] (negative inside)."""
        from shapely.geometry import Point

        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        d = np.array([self.inner.exterior.distance(Point(p)) for p in pts])
        inside = np.array([self.inner.contains(Point(p)) for p in pts], dtype=bool)
        return np.where(inside, -d, d)

    def contact_truth(self, hw, contact):
        """The 2-D toucher settles on the inner shape itself (there is no cover to press on)."""
        return ContactTruth(float(self.true_distance(np.asarray(contact)[None])[0]), True)

    def truth(self) -> dict:
        """The true inner and outer boundaries as closed polylines `(m, 2)` [m]."""
        return {"inner": [self.inner_boundary], "outer": [self.outer_boundary]}

    def __repr__(self) -> str:
        return (f"Scene2D({self.name!r}, inner area={self.inner.area * 1e4:.0f} cm^2, "
                f"outer area={self.outer.area * 1e4:.0f} cm^2, d_H={self.inner_outer_hausdorff() * 100:.1f} cm)")


def paper_objects_2d() -> dict[str, Scene2D]:
    """Objects A-D of the paper's 2-D study (Fig. 3, Table I), built from rectangles [m].

    Inner-outer Hausdorff distances equal Table I (6.4, 12.0, 26.9, 37.5 cm):

    * A, high similarity: a 30 x 20 cm inner rectangle; the outer is the same rectangle grown by 4.5255 cm on
      every side, d_H = corner to corner = 4.5255 * sqrt(2) = 6.4 cm.
    * B, non-convex: a 40 x 30 cm inner rectangle with a 10 x 10 cm notch cut into its top edge; the outer is the
      rectangle grown by 2 cm (a cover spanning the notch), d_H = notch bottom to outer top = 10 + 2 = 12.0 cm.
    * C, local mixing: the outer coincides with the 30 x 20 cm inner on its left, top and bottom edges and
      extends 26.9 cm beyond its right edge, d_H = 26.9 cm.
    * D, low similarity: a 20 x 15 cm inner rectangle in an 80 x 60 cm outer one, d_H = corner to corner =
      sqrt(30^2 + 22.5^2) = 37.5 cm.

    The toucher starts 10 cm outside the outer shape and approaches horizontally, so that the first contact
    lies on a flat face: from the left for A, B and D, and for C from the right, through the 26.9 cm of soft
    cover that extends beyond the inner shape (the approach path is the only place where a sliding toucher
    occupies that region, see docs/method-notes.md).
    """
    g = 0.064 / math.sqrt(2.0)
    a_inner = rectangle(-0.15, 0.15, -0.10, 0.10)
    a_outer = rectangle(-0.15 - g, 0.15 + g, -0.10 - g, 0.10 + g)
    b_inner = np.array([[-0.20, -0.15], [0.20, -0.15], [0.20, 0.15], [0.05, 0.15], [0.05, 0.05],
                        [-0.05, 0.05], [-0.05, 0.15], [-0.20, 0.15]])
    b_outer = rectangle(-0.22, 0.22, -0.17, 0.17)
    c_inner = rectangle(-0.15, 0.15, -0.10, 0.10)
    c_outer = rectangle(-0.15, 0.15 + 0.269, -0.10, 0.10)
    d_inner = rectangle(-0.10, 0.10, -0.075, 0.075)
    d_outer = rectangle(-0.40, 0.40, -0.30, 0.30)
    return {
        "A": Scene2D(a_inner, a_outer, start=(-0.15 - g - 0.10, 0.02), direction=(1, 0), name="A"),
        "B": Scene2D(b_inner, b_outer, start=(-0.32, -0.03), direction=(1, 0), name="B"),
        "C": Scene2D(c_inner, c_outer, start=(0.15 + 0.269 + 0.10, 0.01), direction=(-1, 0), name="C"),
        "D": Scene2D(d_inner, d_outer, start=(-0.50, 0.01), direction=(1, 0), name="D"),
    }


register_world("planar", Scene2D, objects=lambda names, smoke: paper_objects_2d(), object_names=("A", "B", "C", "D"),
               dimension=2,
               description="the paper's 2-D study (Sec. V): polygons and a point fingertip (objects A-D)")
