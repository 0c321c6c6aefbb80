"""When an exploration stops: the paper's rules as objects a world names as its defaults.

* 2-D study (Sec. V-A-2): "terminates when it goes around the inner shape" -> :class:`OnceAround`.
* robot study (Sec. VI-A-2): "terminates when the travel length reaches 1.5 m" -> :class:`TravelBudget`.

Every run also stops at ``max_steps``, when contact is lost, or when the robot refuses a command.

A rule is asked ``check(state)`` with the public :class:`~torch_gpioius.exploration.state.ExplorationState`; one
that needs the estimate (its centre) says so with ``uses_estimate = True`` and is asked after the step's
measurement, the others before it (so that the measurement knows the step is the last).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["StopRule", "OnceAround", "TravelBudget", "gone_around", "largest_uncovered_gap"]


def largest_uncovered_gap(points: np.ndarray, centre: np.ndarray) -> tuple[float, float]:
    """Largest angular gap between 2-D contacts seen from ``centre``, and the chord between its two ends.

    Sorts the contacts' angles about ``centre``; the largest circular difference between neighbours is the
    sector no contact has visited.

    Returns:
        ``(gap_angle [rad], gap_chord [m])``; ``(2 pi, inf)`` for fewer than 2 points.
    """
    p = np.asarray(points, dtype=np.float64)
    if len(p) < 2:
        return 2 * math.pi, math.inf
    rel = p - np.asarray(centre, dtype=np.float64)
    ang = np.arctan2(rel[:, 1], rel[:, 0])
    order = np.argsort(ang)
    a = ang[order]
    gaps = np.diff(np.append(a, a[0] + 2 * math.pi))
    k = int(np.argmax(gaps))
    i, j = order[k], order[(k + 1) % len(order)]
    return float(gaps[k]), float(np.linalg.norm(p[i] - p[j]))


def gone_around(points: np.ndarray, centre: np.ndarray | None, max_gap: float) -> bool:
    """Termination rule: the contacts surround ``centre`` with no unvisited sector wider than ``max_gap``.

    "Once around the inner shape" is read as angular coverage about a point inside the estimate: every
    direction from it has been visited, except sectors whose two bounding contacts lie at most ``max_gap`` [m]
    apart (a gap the GP bridges at its length scale). Coverage rather than the path's winding number, because
    the variance-driven planner may turn back a few centimetres short of closing its loop, where little
    variance is left, and close it later from the other side (docs/method-notes.md, section 6).
    """
    if centre is None or len(points) < 3:
        return False
    angle, chord = largest_uncovered_gap(points, centre)
    return angle < math.pi / 2 and chord <= max_gap


@dataclass(frozen=True)
class StopRule:
    """Base of the stop rules: ``check(state)`` returns the termination reason, or None to go on.

    Attributes:
        uses_estimate: the rule reads the state's estimate (``state.centre``), so it is asked after the step's
            measurement rather than before.
    """

    uses_estimate = False

    def check(self, state) -> str | None:
        raise NotImplementedError

    def describe(self) -> dict:
        return {"rule": type(self).__name__, **self.__dict__}


@dataclass(frozen=True)
class OnceAround(StopRule):
    """The 2-D study's rule: the contacts have gone once around the estimated inner region (:func:`gone_around`).

    Attributes:
        closure_gap: widest unvisited gap (chord between its bounding contacts) that still counts [m]; default
            theta_x / 2 of the paper's 2-D study.
        min_steps: steps before the rule applies.
    """

    closure_gap: float = 0.05
    min_steps: int = 10
    uses_estimate = True

    def check(self, state):
        contacts = np.asarray(state.contacts)
        if contacts.shape[1] != 2:
            return None
        if len(contacts) > self.min_steps and gone_around(contacts, state.centre, self.closure_gap):
            return "once-around"
        return None


@dataclass(frozen=True)
class TravelBudget(StopRule):
    """The robot study's rule: stop once the fingertip has travelled ``max_travel`` [m] since the first contact
    (taps and regulation included)."""

    max_travel: float = 1.5

    def __post_init__(self) -> None:
        if isinstance(self.max_travel, bool) or not (isinstance(self.max_travel, (int, float))
                                                     and math.isfinite(self.max_travel) and self.max_travel > 0):
            raise ValueError(f"max_travel: must be a positive distance [m], got {self.max_travel!r}")
        from ..core.validation import as_length

        as_length(self.max_travel, "max_travel")                  # 150 (mm meant as m) ran to the step cap

    def check(self, state):
        return "travel" if state.travel >= self.max_travel else None
