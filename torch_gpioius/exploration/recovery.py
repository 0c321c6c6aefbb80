"""No run stalls: when the fingertip makes no progress, recover from the free side; after a few failed recoveries,
stop with "stalled".

A run can sit in one place: under an object, below the floor of the exploration range, where the estimated normal
is far off and both the planned step and the range penalty push into the object (a bottle under a tight cover did
so for 357 of 400 steps). :class:`NoProgress` watches the contacts: when none of the last ``window`` steps took the
fingertip more than ``min_progress`` from where it is now, the run is stalled. The recovery lifts the fingertip
along the *measured* contact normal (the force direction, which the estimate cannot bend) until the force lets go,
``lift`` further, and approaches again along the opposite direction; the planner then starts afresh (no previous
direction) and, where the estimate's normal still disagrees with the measured one, plans in the measured tangent
plane (:func:`torch_gpioius.exploration.planning.plan_direction`). A recovery's travel counts in the travel budget
and it counts as a step of the step budget. After ``max_recoveries`` recoveries that did not restore progress the run
ends with ``terminated = "stalled"``: a result, not a missing value.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .evidence import Evidence

__all__ = ["NoProgress"]


@dataclass(frozen=True)
class NoProgress:
    """The no-progress rule and its recovery (see the module docstring).

    Attributes:
        window: steps over which progress is judged.
        min_progress: the fingertip must have been at least this far [m] from its current contact at some step of the
            window (sliding at 1 cm per step moves it several centimetres).
        max_recoveries: recoveries in a row that may fail before the run stops as stalled.
        lift: lift beyond the point where the force let go [m].
        max_lift: longest lift [m].
    """

    window: int = 8
    min_progress: float = 0.01
    max_recoveries: int = 3
    lift: float = 0.02
    max_lift: float = 0.1

    def __post_init__(self) -> None:
        if isinstance(self.window, bool) or not isinstance(self.window, int) or self.window < 2:
            raise ValueError(f"NoProgress.window: must be an integer >= 2, got {self.window!r}")
        if isinstance(self.max_recoveries, bool) or not isinstance(self.max_recoveries, int) or self.max_recoveries < 0:
            raise ValueError(f"NoProgress.max_recoveries: must be an integer >= 0, got {self.max_recoveries!r}")
        for name in ("min_progress", "lift", "max_lift"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 < v <= 1.0):
                raise ValueError(f"NoProgress.{name}: must be in (0, 1] m, got {v!r}")

    def stalled(self, state) -> bool | None:
        """Whether the last ``window`` steps left the fingertip where it is; None while the window since the start
        or the last recovery is not yet full (nothing to judge)."""
        if state.steps - state.last_recovery < self.window or len(state.contacts) <= self.window:
            return None
        recent = np.asarray(state.contacts[-(self.window + 1):])
        return float(np.linalg.norm(recent - recent[-1], axis=1).max()) < self.min_progress

    def recover(self, state, toucher) -> Evidence | None:
        """Lift along the measured normal until the force lets go, then approach again; None if the robot refused."""
        if state.normal is None:
            return None
        try:
            up = toucher.lift(state.normal, step=0.005, until_force_below=0.1, extra=self.lift,
                              max_distance=self.max_lift)
            back = toucher.approach(-state.normal, max_travel=float(up.travel) + 0.05)
        except RuntimeError:
            return None
        return Evidence([up, back], back.contact.numpy() if back.in_contact else None,
                        back.force_normal if back.in_contact else None, kind="recovery")

    def describe(self) -> dict:
        return asdict(self)
