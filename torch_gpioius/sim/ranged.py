"""The base of the 3-D worlds explored inside a box (the force-field world, MuJoCo): the range's checks, its
penalty (eq. 25) and the true surface's samples within it, written once."""

from __future__ import annotations

import abc

import numpy as np

from ..exploration.world import World
from ..exploration.planning import RangePenalty

__all__ = ["RangedScene"]


class RangedScene(World):
    """A world whose exploration range is a box ``range`` `(2, 3)` [min corner; max corner] [m] (trimesh's
    ``mesh.bounds`` layout): the planner's penalty keeps the fingertip inside it, the metrics are evaluated inside it.

    A subclass sets ``range`` and ``_inner_samples = {}`` (the samples' cache) and implements
    :meth:`true_surface_samples`.
    """

    range: np.ndarray
    #: The converged ruler (:func:`torch_gpioius.sim.forcefield.estimate_metrics_3d`): marching cubes on a 1 cm grid,
    #: the vertices moved onto mu = 0, the facets split to 1 cm on it and their chords corrected. Runs measured before
    #: carry none (marching cubes on a 2 cm grid alone).
    ruler = "projected: 1 cm grid, vertices on mu = 0, 1 cm facets corrected to the level set"

    @abc.abstractmethod
    def true_surface_samples(self, spacing: float) -> np.ndarray:
        """`(n, 3)` samples of the whole true inner surface [m], about one per ``spacing``^2."""

    def bounds(self, margin: float = 0.05) -> np.ndarray:
        """`(2, 3)` grid box [min; max] for surfaces and metrics: the exploration range grown by ``margin`` [m]."""
        return self.range + np.array([[-margin], [margin]])

    def in_range(self, points: np.ndarray) -> np.ndarray:
        """`(n,)` bool: points `(n, 3)` inside the exploration range."""
        p = np.asarray(points, dtype=np.float64)
        return ((p >= self.range[0]) & (p <= self.range[1])).all(axis=1)

    def inner_samples_in_range(self, spacing: float = 0.003) -> np.ndarray:
        """`(n, 3)` samples of the true inner surface inside the exploration range, about one per ``spacing``^2
        (the reference of the Hausdorff metric; computed once per spacing and world)."""
        if spacing not in self._inner_samples:
            pts = self.true_surface_samples(spacing)
            self._inner_samples[spacing] = pts[self.in_range(pts)]
        return self._inner_samples[spacing]

    def inner_quadrature(self, edge: float = 0.003) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A quadrature of the true inner surface inside the exploration range (the shape metrics' reference;
        computed once per edge and world): ``(centroids (k, 3), areas (k,), vertices (v, 3))`` of the inner mesh's
        facets split to edges of at most ``edge`` [m] (:func:`torch_gpioius.geometry.metrics.mesh_quadrature`), those
        whose centroid (vertex) lies in the range."""
        from ..geometry.metrics import mesh_quadrature

        cache = self.__dict__.setdefault("_inner_quadrature", {})
        if edge not in cache:
            c, w, v = mesh_quadrature(self.inner, edge)
            keep = self.in_range(c)
            cache[edge] = (c[keep], w[keep], v[self.in_range(v)])
        return cache[edge]

    def range_penalty(self, beta: float = 100.0) -> RangePenalty:
        """The paper's C(x) (eq. 25, beta = 100) for this world's exploration range."""
        return RangePenalty(self.range[0], self.range[1], beta=beta)
