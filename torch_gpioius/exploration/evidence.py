"""Evidence-seeking exploration (beyond the paper): taps that record free space inside the cover.

A sliding fingertip occupies the gap between a loose cover and the body only on its approach, so the only inner
evidence that the cover is not the body is gathered at the start; the learned correlation then sits on 1, vision
pulls the estimate onto the cover, and the planner (which follows the inner variance) has no reason to go where
the estimate is wrong (docs/results-3d.md, object H). A *tap* gathers that evidence on purpose: lift the fingertip
along the measured force direction until the cover's force on it vanishes and it is beyond the outer surface the
camera saw (``mu_out >= 0``; plus a margin), then come back down to the body. The readings below the contact threshold are inner free space, the re-approach ends on the body again.

**When to tap** (:meth:`TapPolicy.due`), from the model's own state, at most every ``min_steps`` steps:

1. *the similarity is not yet settled*: the profile-likelihood interval of the task correlation
   (:meth:`torch_gpioius.GPIOIS.similarity_interval`) still contains 1;
2. *a tap can inform it*: at the contact the outer estimate lies at least ``min_gap`` beyond the inner surface
   (first-order distance ``-mu_out / |grad mu_out|`` along the normal). A tap records free space only
   ``free_space_margin`` away from contacts, so over a tight cover it would record nothing: no tap.

A tap's travel (lift and re-approach) counts in the travel budget, and each tap counts as a step of the step budget.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

__all__ = ["TapPolicy"]


@dataclass(frozen=True)
class TapPolicy:
    """When and how to tap.

    Attributes:
        min_steps: steps between two taps (and before the first).
        min_gap: least estimated distance [m] between the contact and the outer estimate for a tap to be useful
            (default: the free-space margin of 2 cm plus one sample spacing).
        level: confidence level of the correlation interval.
        lift_step: length of each lift move [m].
        vanish_force: ``|F|`` [N] below which the cover no longer pushes on the fingertip (several times the
            OptoForce's 0.02 N noise).
        extra_lift: lift beyond the point where the force vanished [m].
        max_lift: longest lift [m].
        local_correlation: with a similarity per region (``regions=R``), the local correlation at the contact at or
            above which a tap is due (those models have no profile interval).
    """

    min_steps: int = 8
    min_gap: float = 0.03
    level: float = 0.95
    lift_step: float = 0.005
    vanish_force: float = 0.1
    extra_lift: float = 0.01
    max_lift: float = 0.2
    local_correlation: float = 0.9

    def due(self, state) -> bool:
        """Whether to tap after the current step (see the module docstring)."""
        if state.steps - getattr(state, "last_tap", 0) < self.min_steps:
            return False
        model = state.model
        x = torch.as_tensor(state.contacts[-1], dtype=model.train_inputs[0].dtype).reshape(1, -1)
        xg = x.clone().requires_grad_(True)
        mu, _ = model.predict(xg, task=1)
        grad, = torch.autograd.grad(mu.sum(), xg)
        mu_out, g = float(mu.detach()), float(grad.norm())
        gap = -mu_out / g if g > 0 and mu_out < 0 else 0.0
        if gap < self.min_gap:
            return False
        if hasattr(model, "correlation_at"):       # a similarity per region: its point estimate at the contact
            return float(model.correlation_at(x.detach())[0]) >= self.local_correlation
        from ..inference.interval import plausible_correlation

        engine = model._inference()
        x0 = model.train_inputs[0]
        return plausible_correlation(lambda kt: engine.mll_derivatives(kt.to(dtype=x0.dtype, device=x0.device)),
                                     model.task_covariance, 1.0, self.level)

    def tap(self, state, hw, world, policy) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
        """Lift along the measured force direction until the cover lets go, then re-approach the body.

        Returns:
            ``(x_new (k, d), y_new (k,), removed (j,), travel)``: the inner observations the tap adds (free space
            y = 1 and, when it lands elsewhere, the new contact y = 0), the indices retracted, the travel [m]; None
            when the robot refused the tap (the exploration then continues without it).
        """
        from .observations import retract_free_space, thin_points

        normal = state.normal
        state.last_tap = state.steps
        model = state.model
        x0 = model.train_inputs[0]

        def inside_outer(p) -> bool:     # still inside the outer surface the camera saw
            with torch.no_grad():
                q = torch.as_tensor(p, dtype=x0.dtype).reshape(1, -1)
                return float(model.predict(q, task=1)[0][0]) < 0.0

        try:
            lift = hw.controller.lift(normal, step=self.lift_step, until_force_below=self.vanish_force,
                                      extra=self.extra_lift, max_distance=self.max_lift, inside=inside_outer)
            back = hw.controller.approach(-normal, max_travel=float(lift.travel) + 0.05)
        except RuntimeError:          # refused or faulted: no tap this time
            return None
        travel = float(lift.travel + back.travel)
        state.travel += travel
        state.taps += 1
        state.path.extend(lift.path.numpy())
        state.path.extend(back.path.numpy())
        free = np.concatenate([lift.free_space.numpy(), back.free_space.numpy()])
        xs, ys = [], []
        removed = np.zeros(0, dtype=np.int64)
        if back.in_contact:
            contact = back.contact.numpy()
            if np.linalg.norm(contact - state.contacts[-1]) >= 0.005:
                removed = retract_free_space(state.model, contact, policy.free_space_margin)
                state.retracted += len(removed)
                xs.append(contact[None])
                ys.append(np.zeros(1))
            state.contacts[-1] = contact
            state.normal = back.force_normal
        free = thin_points(free, policy.free_space_spacing, np.asarray(state.contacts), policy.free_space_margin)
        if len(free):
            xs.append(free)
            ys.append(np.ones(len(free)))
        if not xs:
            return np.zeros((0, state.contacts[-1].shape[0])), np.zeros(0), removed, travel
        x_new, y_new = np.concatenate(xs), np.concatenate(ys)
        state.model.add_observations(x_new, y_new, 0)
        return x_new, y_new, removed, travel
