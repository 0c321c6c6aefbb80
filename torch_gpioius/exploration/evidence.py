"""Evidence-seeking exploration (beyond the paper): taps that record free space inside the cover.

A sliding fingertip occupies the gap between a loose cover and the body only on its approach, so the only inner
evidence that the cover is not the body is gathered at the start; the learned correlation then sits on 1, vision
pulls the estimate onto the cover, and the planner (which follows the inner variance) has no reason to go where
the estimate is wrong (docs/results-3d.md, object H). A *tap* gathers that evidence on purpose: lift the fingertip
along the measured force direction until the cover's force on it vanishes and it is beyond the outer surface the
camera saw (``mu_out >= 0``; plus a margin), then come back down to the body. The readings below the contact threshold
are inner free space, the re-approach ends on the body again.

**When to tap** (:meth:`TapPolicy.due`), from the exploration's state, at most every ``min_steps`` steps:

1. *the similarity is not yet settled*: the profile-likelihood interval of the task correlation
   (:meth:`torch_gpioius.GPIOIS.similarity_interval`) still contains 1;
2. *a tap can inform it*: at the contact the outer estimate lies at least ``min_gap`` beyond the inner surface
   (first-order distance ``-mu_out / |grad mu_out|`` along the normal). A tap records free space only
   ``free_space_margin`` away from contacts, so over a tight cover it would record nothing: no tap.

A tap's travel (lift and re-approach) counts in the travel budget, and each tap counts as a step of the step budget.

A policy is any object with ``due(state)`` and ``gather(state, toucher)`` (the
:class:`~torch_gpioius.exploration.protocols.EvidencePolicy` contract): ``explore(..., evidence=MyPolicy())``. It
reads the public state and moves through the toucher; it returns an :class:`Evidence`, and the loop turns that into
observations exactly as it does a sliding step's touch.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import torch

from .protocols import EvidencePolicyBase

__all__ = ["Evidence", "TapPolicy"]


@dataclass
class Evidence:
    """What an evidence policy gathered; the loop turns it into observations as it does a step's touch.

    Attributes:
        touches: the contact controller's results, in order (for a tap: the lift, then the re-approach). Their
            travel counts in the travel budget, their free space (``|F|`` below the contact threshold) becomes inner
            free space.
        contact: `(d,)` where the fingertip rests on the body afterwards [m], or None if it did not come back to it.
        normal: the measured contact normal there `(d,)`, or None.
        min_move: a contact that moved less than this from the previous one [m] is not a new observation.
        kind: "tap" (an evidence policy's action, counted in ``state.taps``) or "recovery" (a stall's recovery,
            counted in ``state.recoveries``).
    """

    touches: list = field(default_factory=list)
    contact: np.ndarray | None = None
    normal: torch.Tensor | None = None
    min_move: float = 0.005
    kind: str = "tap"


@dataclass(frozen=True)
class TapPolicy(EvidencePolicyBase):
    """When and how to tap (see the module docstring).

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
    name: str = "taps"
    #: a tap is about the similarity, which only a camera's outer task has
    needs_vision = True

    def due(self, state) -> bool:
        """Whether to tap after the current step (see the module docstring); reads the state, changes nothing."""
        if state.steps - state.last_evidence < self.min_steps:
            return False
        model = state.model
        x = torch.as_tensor(state.contact, dtype=model.train_inputs[0].dtype).reshape(1, -1)
        xg = x.clone().requires_grad_(True)
        mu = model.predict_mean(xg, task=1)
        grad, = torch.autograd.grad(mu.sum(), xg)
        mu_out, g = float(mu.detach()), float(grad.norm())
        gap = -mu_out / g if g > 0 and mu_out < 0 else 0.0
        if gap < self.min_gap:
            return False
        if hasattr(model, "correlation_at"):       # a similarity per region: its point estimate at the contact
            return float(model.correlation_at(x.detach())[0]) >= self.local_correlation
        return model.correlation_plausible(1.0, self.level)

    def gather(self, state, toucher) -> Evidence | None:
        """Lift along the measured force direction until the cover lets go and the fingertip is beyond the outer
        surface the camera saw, then re-approach the body.

        Returns:
            the :class:`Evidence` (lift and re-approach), or None when the robot refused (the exploration goes on
            without it).
        """
        normal = state.normal
        model = state.model
        x0 = model.train_inputs[0]

        def inside_outer(p) -> bool:     # still inside the outer surface the camera saw
            with torch.no_grad():
                q = torch.as_tensor(p, dtype=x0.dtype).reshape(1, -1)
                return float(model.predict_mean(q, task=1)[0]) < 0.0

        try:
            lift = toucher.lift(normal, step=self.lift_step, until_force_below=self.vanish_force,
                                extra=self.extra_lift, max_distance=self.max_lift, inside=inside_outer)
            back = toucher.approach(-normal, max_travel=float(lift.travel) + 0.05)
        except RuntimeError:          # refused or faulted: no tap this time
            return None
        return Evidence([lift, back], back.contact.numpy() if back.in_contact else None,
                        back.force_normal if back.in_contact else None)

    def describe(self) -> dict:
        return asdict(self)
