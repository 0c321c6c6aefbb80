"""The cover's gap over the body: a smooth field regressed from the gaps the touches measure.

A cover does not stand off a body by one gap: cloth sags between supports, lies thick on one side and thin on
another. Each contact under seen cover measures the gap where it is (its distance from the seen cover's local
plane, :class:`torch_gpioius.exploration.observations.CoverGap`); :class:`GapField` regresses those gaps over the
cover by a small GP of its own (a squared-exponential kernel over the contacts' feet on the cover, the gaps' median
as its prior mean), and the outer task's prior mean ``1 - g(x) / ramp`` (:meth:`GPIOIS.set_outer_mean
<torch_gpioius.models.GPIOIS.set_outer_mean>`) then stands for the gap at each place instead of one gap everywhere.

The field's three hyper-parameters (its length, how far the gap strays from the median, and how noisily a contact
measures it) are chosen on a fixed grid by the field's exact log marginal likelihood: a handful of candidates, each a
Cholesky of at most a few hundred contacts, with no local optimum to start from and the same choice on every CPU
(written here because GPyTorch's ExactGP would fit them by gradient steps from one start, for a regression that
takes a millisecond).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import torch
from torch import Tensor

from ..core.validation import INSIDE_DEPTH_MAX, as_float, as_points

__all__ = ["GapField", "GAP_LENGTHS", "GAP_SCALES", "GAP_NOISES"]

#: The field's candidate lengths [m]: a gap that varies over a hand's width to one that varies over a body.
GAP_LENGTHS = (0.04, 0.08, 0.16)
#: How far the gap may stray from its median, prior standard deviations [m].
GAP_SCALES = (0.005, 0.01, 0.02)
#: How noisily one contact measures the gap, standard deviations [m] (the cover's local plane through a few voxel
#: averages, the fingertip's settling).
GAP_NOISES = (0.002, 0.004, 0.008)


class GapField:
    """The cover's gap ``g(x)`` [m] over the body: the posterior mean of a GP regression of the touches' gaps.

    ``g(x) = g0 + k(x, P) (K + s_n^2 I)^-1 (g - g0)``, ``k(x, x') = s^2 exp(-|x - x'|^2 / (2 L^2))``, clipped to
    ``[0, INSIDE_DEPTH_MAX]``: ``g0`` the gaps' median, ``P`` the contacts' feet on the seen cover (where the field is
    read: at the camera's observations), ``L``, ``s`` and ``s_n`` chosen by :meth:`fit`.

    Args:
        points: `(k, d)` where each gap was measured, base frame [m] (the contacts' feet on the seen cover).
        gaps: `(k,)` the measured gaps [m], each in ``[0, INSIDE_DEPTH_MAX]``.
        length: the field's length ``L`` [m].
        scale: the prior standard deviation ``s`` of the gap about ``g0`` [m].
        noise: one measurement's standard deviation ``s_n`` [m].
        prior: ``g0`` [m]; None: the median of ``gaps``.
        ramp: the distance [m] over which the labels rise from 0 on a surface to 1 in free space
            (:attr:`ObservationPolicy.ramp <torch_gpioius.models.ObservationPolicy.ramp>`): a gap ``g`` is ``g / ramp``
            label units (:meth:`mean`).
        carry: a constant added to the mean [label units], ``1 / r - 1`` for the transfer ``r = K_t[0,1] /
            K_t[1,1]`` a fit learned (:meth:`carried`; ``ObservationPolicy.cover_carry``), in [-1, 1]; 0: none.

    Raises:
        ValueError: points or gaps malformed, not finite, of different counts or none; a gap outside
            ``[0, INSIDE_DEPTH_MAX]``; a length, scale or noise not a positive number; a carry outside [-1, 1].
    """

    def __init__(self, points, gaps, length: float, scale: float, noise: float, prior: float | None = None,
                 ramp: float = 0.05, carry: float = 0.0):
        if not torch.is_tensor(points):     # lists of Python floats would become float32 tensors
            try:
                points = np.asarray(points, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"points: cannot be read as numbers ({exc})") from None
        p = as_points(points, "points")
        g = np.asarray(gaps, dtype=np.float64).reshape(-1) if not torch.is_tensor(gaps) else (
            gaps.detach().cpu().double().reshape(-1).numpy())
        if len(p) == 0 or len(g) != len(p):
            raise ValueError(f"gaps: expected one gap per point ({len(p)}), got {len(g)}")
        if not (np.isfinite(g).all() and (g >= 0).all() and (g <= INSIDE_DEPTH_MAX).all()):
            raise ValueError(f"gaps: must be finite and in [0, {INSIDE_DEPTH_MAX:g}] m")
        self.length = as_float(length, "length", positive=True)
        self.scale = as_float(scale, "scale", positive=True)
        self.noise = as_float(noise, "noise", positive=True)
        self.ramp = as_float(ramp, "ramp", positive=True)
        self.carry = as_float(carry, "carry", lo=-1.0, hi=1.0)
        self.prior = float(np.median(g)) if prior is None else as_float(prior, "prior", lo=0.0, hi=INSIDE_DEPTH_MAX)
        self.points = p.detach().cpu().double()
        self.gaps = torch.as_tensor(g, dtype=torch.float64)
        chol = torch.linalg.cholesky(self._gram())
        self._alpha = torch.cholesky_solve((self.gaps - self.prior).unsqueeze(-1), chol).squeeze(-1)
        self._chol = chol

    def _kernel(self, x: Tensor, z: Tensor) -> Tensor:
        return self.scale ** 2 * torch.exp(-0.5 * torch.cdist(x, z).square() / self.length ** 2)

    def _gram(self) -> Tensor:
        return self._kernel(self.points, self.points) + self.noise ** 2 * torch.eye(len(self.points),
                                                                                     dtype=torch.float64)

    def log_marginal_likelihood(self) -> float:
        """The field's exact log marginal likelihood of the gaps (about the prior ``g0``)."""
        r = self.gaps - self.prior
        return float(-0.5 * r @ self._alpha - torch.log(torch.diagonal(self._chol)).sum()
                     - 0.5 * len(r) * math.log(2 * math.pi))

    @classmethod
    def fit(cls, points, gaps, ramp: float = 0.05, lengths=GAP_LENGTHS, scales=GAP_SCALES,
            noises=GAP_NOISES) -> "GapField":
        """The field whose length, scale and noise, among the grid's, give the gaps the highest exact log marginal
        likelihood (ties: the first, in the grid's order).

        Args:
            points: `(k, d)` where the gaps were measured [m].
            gaps: `(k,)` the gaps [m].
            ramp: the labels' ramp [m] (the constructor's).
            lengths, scales, noises: the candidates [m].

        Raises:
            ValueError: as the constructor, or an empty grid.
        """
        grid = list(itertools.product(lengths, scales, noises))
        if not grid:
            raise ValueError("fit: the grid of lengths, scales and noises is empty")
        best, best_mll = None, -math.inf
        for length, scale, noise in grid:
            field = cls(points, gaps, length, scale, noise, ramp=ramp)
            mll = field.log_marginal_likelihood()
            if mll > best_mll:
                best, best_mll = field, mll
        return best if best is not None else cls(points, gaps, *grid[0], ramp=ramp)

    def gap(self, x) -> Tensor:
        """The gap [m] at `(n, d)` points (tensor or array, base frame [m]): `(n,)` float64, in
        ``[0, INSIDE_DEPTH_MAX]``; differentiable in ``x`` where not clipped."""
        x = torch.as_tensor(x, dtype=torch.float64)
        pts = self.points.to(x.device)
        g = self.prior + self._kernel(x, pts) @ self._alpha.to(x.device)
        return g.clamp(0.0, INSIDE_DEPTH_MAX)

    def mean(self, x) -> Tensor:
        """The outer task's prior mean ``1 - g(x) / ramp + carry`` at `(n, d)` points [label units]: `(n,)`."""
        return 1.0 - self.gap(x) / self.ramp + self.carry

    @property
    def constant_mean(self) -> float:
        """The outer mean the median gap stands for, ``1 - g0 / ramp + carry`` (what one mean for the whole cover
        was)."""
        return 1.0 - self.prior / self.ramp + self.carry

    def carried(self, carry: float) -> "GapField":
        """The same field (its gaps, places and numbers) with the mean raised by ``carry`` [label units] in place of
        its own (:func:`~torch_gpioius.exploration.observations.carried_mean`'s ``1 / r - 1``)."""
        return GapField(self.points, self.gaps, self.length, self.scale, self.noise, self.prior, self.ramp, carry)

    def as_dict(self) -> dict:
        """The field as plain numbers (a log's or checkpoint's record): :meth:`from_dict` rebuilds it exactly (the
        carry only when it is not 0, so that records written before it existed read alike)."""
        out = {"points": self.points.tolist(), "gaps": self.gaps.tolist(), "length": self.length,
               "scale": self.scale, "noise": self.noise, "prior": self.prior, "ramp": self.ramp}
        if self.carry:
            out["carry"] = self.carry
        return out

    @classmethod
    def from_dict(cls, record: dict, where: str = "gap field") -> "GapField":
        """The field :meth:`as_dict` wrote; ValueError naming ``where`` for a record that is not one."""
        try:
            return cls(record["points"], record["gaps"], record["length"], record["scale"], record["noise"],
                       record["prior"], record.get("ramp", 0.05), record.get("carry", 0.0))
        except (KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"{where}: not a gap field record ({exc!r})") from None

    def __eq__(self, other) -> bool:
        return isinstance(other, GapField) and self.as_dict() == other.as_dict()

    __hash__ = None

    def __repr__(self) -> str:
        carry = f", carry {self.carry:.3g}" if self.carry else ""
        return (f"GapField({len(self.points)} gaps, median {self.prior * 100:.1f} cm, length {self.length:g} m, "
                f"scale {self.scale:g} m, noise {self.noise:g} m{carry})")
