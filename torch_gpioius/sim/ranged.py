"""The base of the 3-D worlds explored inside a box (the force-field world, MuJoCo): the range's checks, its
penalty (eq. 25) and the true surface's samples within it, written once."""

from __future__ import annotations

import abc

import numpy as np

from ..exploration.world import World
from ..planning import RangePenalty

__all__ = ["RangedScene"]


class RangedScene(World):
    """A world whose exploration range is a box ``range`` `(2, 3)` [min corner; max corner] [m] (trimesh's
    ``mesh.bounds`` layout): the planner's penalty keeps the fingertip inside it, the metrics are evaluated inside it.

    A subclass sets ``range`` and ``_inner_samples = {}`` (the samples' cache) and implements
    :meth:`true_surface_samples`.
    """

    range: np.ndarray

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

    def range_penalty(self, beta: float = 100.0) -> RangePenalty:
        """The paper's C(x) (eq. 25, beta = 100) for this world's exploration range."""
        return RangePenalty(self.range[0], self.range[1], beta=beta)
