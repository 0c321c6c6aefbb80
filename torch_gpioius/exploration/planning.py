"""Sliding-motion planning, eq. (6)-(8) / (17)-(19), with the workspace penalty of eq. (25)."""

from __future__ import annotations

import math

from dataclasses import dataclass

import torch
from torch import Tensor

from ..geometry.differential import surface_geometry

__all__ = ["ZeroPenalty", "RangePenalty", "PlannedStep", "plan_direction"]


class ZeroPenalty:
    """C(x) = 0 everywhere (the 2-D study, Sec. V-A-1)."""

    def __call__(self, x: Tensor) -> Tensor:
        """`(m, d)` -> `(m,)` zeros (keeps the autograd graph of x)."""
        return x.sum(-1) * 0.0


class RangePenalty:
    r"""Range penalty of eq. (25): ``C(x) = -beta dist(x)^2`` outside an allowed box, 0 inside.

    ``dist(x)`` is the Euclidean distance from x to the box [m]; ``C < 0`` marks where the robot cannot go.

    Args:
        lower: `(d,)` box minimum [m], base frame.
        upper: `(d,)` box maximum [m].
        beta: weight [1/m^2 in units of V], 100 in the paper.
    """

    def __init__(self, lower, upper, beta: float = 100.0):
        self.lower = torch.as_tensor(lower, dtype=torch.float64)
        self.upper = torch.as_tensor(upper, dtype=torch.float64)
        if self.lower.shape != self.upper.shape or not (self.upper > self.lower).all():
            raise ValueError("RangePenalty: lower and upper must have the same shape with lower < upper")
        self.beta = float(beta)

    def distance(self, x: Tensor) -> Tensor:
        """`(m,)` distance from `(m, d)` points to the box (0 inside) [m]."""
        lo, hi = self.lower.to(x), self.upper.to(x)
        excess = torch.clamp(lo - x, min=0.0) + torch.clamp(x - hi, min=0.0)
        return excess.norm(dim=-1)

    def __call__(self, x: Tensor) -> Tensor:
        lo, hi = self.lower.to(x), self.upper.to(x)
        excess = torch.clamp(lo - x, min=0.0) + torch.clamp(x - hi, min=0.0)
        return -self.beta * excess.pow(2).sum(-1)


@dataclass
class PlannedStep:
    """A planned sliding step.

    Attributes:
        direction: `(d,)` step d* [m], length alpha.
        normal: `(d,)` estimated outward unit normal at x (zero if undefined).
        objective_gradient: `(d,)` gradient of L = V + C at x.
        projected_gradient_norm: |P grad L|.
        fallback: "" for the regular eq. (19) step, else which degenerate-case rule was used.
    """

    direction: Tensor
    normal: Tensor
    objective_gradient: Tensor
    projected_gradient_norm: float
    fallback: str


def _tangent_fallback(normal: Tensor, previous: Tensor | None) -> tuple[Tensor, str]:
    d = normal.shape[-1]
    if previous is not None:
        t = previous - (previous @ normal) * normal
        if t.norm() > 1e-9:
            return t / t.norm(), "previous-direction"
    if d == 2:
        t = torch.stack([-normal[1], normal[0]])  # normal rotated +90 deg: counter-clockwise around the shape
        if t.norm() > 0.5:
            return t, "counter-clockwise"
    eye = torch.eye(d, dtype=normal.dtype, device=normal.device)
    for k in range(d):  # first base axis with a usable tangential component
        t = eye[k] - (eye[k] @ normal) * normal
        if t.norm() > 0.1:
            return t / t.norm(), f"axis-{k}"
    return eye[0], "axis-0"


#: Angle between the estimate's normal and the measured contact normal beyond which the planner trusts the measurement
#: (:func:`plan_direction`).
MAX_NORMAL_DISAGREEMENT = math.radians(60.0)


def plan_direction(model, x, step: float = 0.01, penalty=None, task: int = 0,
                   previous: Tensor | None = None, measured_normal: Tensor | None = None,
                   max_disagreement: float = MAX_NORMAL_DISAGREEMENT) -> PlannedStep:
    r"""Next sliding direction at the current contact, eq. (19):

    .. math:: d^* = \alpha\, P_\mu(x) \nabla L(x) / \|P_\mu(x) \nabla L(x)\|,\quad L = V + C

    with ``P = I - n n^T`` from the posterior mean gradient (eq. 20-22) of the inner task.

    Degenerate cases, handled deterministically:

    * ``|P grad L| <= 1e-12 (1 + |grad L|)`` (e.g. at a variance extremum, or a symmetric configuration): step along
      the previous direction projected onto the tangent plane; without one, in 2-D along the normal rotated by
      +90 deg (counter-clockwise around the shape), in 3-D along the first base axis with a tangential component.
    * undefined normal (``|grad mu| <= tol.normal_eps``): no tangency constraint can be formed, so ``P = I`` and
      the step follows ``grad L`` itself (or the rules above if that vanishes too).
    * the estimate's normal disagrees with the **measured** contact normal (the force direction) by more than
      ``max_disagreement``, or is undefined while a measurement exists: the step is projected onto the measured
      tangent plane instead (``fallback = "measured-normal"``), so it never points into the object where the
      estimate has it wrong (a fingertip under an object, its estimated normal 100 deg off, was pushed into it).

    Args:
        model: ``GPIOIS`` or ``GPIS`` (task 0 is used for both mean and variance).
        x: `(d,)` current contact position [m], base frame.
        step: step length alpha [m].
        penalty: callable C(x) `(m, d)` -> `(m,)` (default: ``ZeroPenalty``).
        task: task whose posterior drives the plan (0, inner).
        previous: `(d,)` previous direction, for the degenerate-case rule.
        measured_normal: `(d,)` outward contact normal measured at ``x`` (the force direction), or None.
        max_disagreement: angle [rad] between the two normals beyond which the measured one rules.

    Returns:
        ``PlannedStep``.

    Raises:
        ValueError: ``step`` is not a positive finite length of at most 1 m.
    """
    from ..core.validation import as_length

    step = as_length(step, "step", hi=1.0)          # NaN gave a NaN direction, 0 a zero one
    penalty = penalty if penalty is not None else ZeroPenalty()
    x0 = model.train_inputs[0]
    xq = torch.as_tensor(x, dtype=x0.dtype, device=x0.device).reshape(1, -1)
    geo = surface_geometry(model, xq, task)
    xg = xq.detach().clone().requires_grad_(True)
    with torch.enable_grad():
        grad_c, = torch.autograd.grad(penalty(xg).sum(), xg)
    grad_l = (geo.grad_var + grad_c)[0]
    normal = geo.normal[0]
    projector = geo.projector[0]
    guard = ""
    if measured_normal is not None:
        nm = torch.as_tensor(measured_normal, dtype=x0.dtype, device=x0.device).reshape(-1)
        if bool(torch.isfinite(nm).all()) and float(nm.norm()) > 0.5:
            nm = nm / nm.norm()
            if not bool(geo.normal_defined[0]) or float(normal @ nm) < math.cos(max_disagreement):
                normal, guard = nm, "measured-normal"
                projector = torch.eye(len(nm), dtype=nm.dtype, device=nm.device) - torch.outer(nm, nm)
    projected = projector @ grad_l
    pnorm = float(projected.norm())
    fallback = ""
    if pnorm > 1e-12 * (1.0 + float(grad_l.norm())):
        unit = projected / pnorm
    else:
        prev = None if previous is None else torch.as_tensor(previous, dtype=x0.dtype, device=x0.device)
        unit, fallback = _tangent_fallback(normal, prev)
    if guard:
        fallback = guard if not fallback else f"{guard}, {fallback}"
    elif not bool(geo.normal_defined[0]):
        fallback = fallback or "undefined-normal"
    return PlannedStep(step * unit, normal, grad_l, pnorm, fallback)
