"""2-D world of the paper's simulation (Sec. V): a point-mass toucher, a rigid inner polygon and a soft outer
polygon it passes through. Geometry by shapely."""

from __future__ import annotations

import math

import numpy as np
from shapely.geometry import LineString, Point, Polygon

from ..metrics import hausdorff_distance

__all__ = ["Scene2D", "paper_objects_2d", "rectangle"]


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


class Scene2D:
    """A covered object in the plane, seen from outside and touched by a point-mass toucher.

    Args:
        inner: `(k, 2)` vertices of the rigid inner polygon [m].
        outer: `(l, 2)` vertices of the soft outer polygon [m] (must contain the inner one).
        start: `(2,)` toucher start position [m], outside the outer polygon.
        direction: `(2,)` approach direction (normalised here).
        name: label for figures and records.

    Raises:
        ValueError: invalid polygons, an outer that does not contain the inner, a start inside the outer
            shape, or an approach ray that misses the inner shape.
    """

    def __init__(self, inner, outer, start, direction, name: str = ""):
        self.inner = _polygon(inner, "inner")
        self.outer = _polygon(outer, "outer")
        if not self.outer.buffer(1e-9).contains(self.inner):
            raise ValueError("outer: must contain the inner polygon (a cover around the object)")
        self.start = np.asarray(start, dtype=np.float64).reshape(2)
        d = np.asarray(direction, dtype=np.float64).reshape(2)
        if not np.isfinite(d).all() or np.linalg.norm(d) == 0:
            raise ValueError("direction: must be a finite non-zero 2-vector")
        self.direction = d / np.linalg.norm(d)
        if self.outer.contains(Point(self.start)):
            raise ValueError("start: must lie outside the outer polygon")
        self.name = name
        self.first_contact()  # raises if the approach misses

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
        """`(2, 2)` [[x_min, x_max], [y_min, y_max]] of the outer shape and the start, plus ``margin`` [m]."""
        x0, y0, x1, y1 = self.outer.bounds
        x0, x1 = min(x0, self.start[0]), max(x1, self.start[0])
        y0, y1 = min(y0, self.start[1]), max(y1, self.start[1])
        return np.array([[x0 - margin, x1 + margin], [y0 - margin, y1 + margin]])

    def inner_outer_hausdorff(self) -> float:
        """Hausdorff distance between the inner and outer boundaries (Table I) [m]."""
        return hausdorff_distance([self.inner_boundary], [self.outer_boundary], spacing=2e-4)

    def first_contact(self) -> np.ndarray:
        """`(2,)` first point of the inner boundary hit from ``start`` along ``direction`` [m]."""
        far = self.start + self.direction * 10.0 * (1.0 + np.abs(self.start).max())
        hit = LineString([self.start, far]).intersection(self.inner.exterior)
        points = [np.asarray(c) for g in getattr(hit, "geoms", [hit]) if not g.is_empty for c in g.coords]
        if not points:
            raise ValueError("direction: the approach ray from start misses the inner polygon")
        return min(points, key=lambda p: float(np.linalg.norm(p - self.start)))

    def settle(self, x: np.ndarray) -> np.ndarray:
        """Where a compliant fingertip at ``x`` comes to rest on the rigid inner surface [m].

        The toucher passes through the soft outer material. At ``x`` it is pressed onto (or, if it penetrates
        the inner shape after a step into a concave part, pushed back out of) the rigid inner shape, ending at
        the nearest point of the inner boundary (docs/method-notes.md, section 3).

        Args:
            x: `(2,)` position after the tangential step [m].

        Returns:
            `(2,)` contact point on the inner boundary [m].
        """
        boundary = self.inner.exterior
        return np.asarray(boundary.interpolate(boundary.project(Point(np.asarray(x, dtype=np.float64)))).coords[0])

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
