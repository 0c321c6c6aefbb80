"""Touch models: what one touch tells about the inner shape, as an observation batch (the point touch of the paper;
tactile patches are the same contract with many points)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .observations import Observations, ObservationPolicy, thin_points

__all__ = ["PointTouch", "TOUCH_MODELS", "touch_model"]


@dataclass(frozen=True)
class PointTouch:
    """A fingertip with a force sensor (Sec. VI): the settled contact point (y = 0) and the free space it crossed
    with ``|F|`` below the contact threshold (y = 1), thinned to ``policy.free_space_spacing`` and kept
    ``policy.free_space_margin`` from every contact (docs/method-notes.md)."""

    name: str = "point"

    def observations(self, result, contacts: np.ndarray, policy: ObservationPolicy, step: int) -> Observations:
        """The batch of one touch that ended in contact at ``contacts[-1]``."""
        contact = np.asarray(contacts[-1], dtype=np.float64)
        free = thin_points(result.free_space.numpy(), policy.free_space_spacing, np.asarray(contacts),
                           policy.free_space_margin)
        return Observations(np.concatenate([contact[None], free]), np.r_[0.0, np.ones(len(free))],
                            np.zeros(1 + len(free), np.int64), step=step, source="touch")

    def describe(self) -> dict:
        return {"touch": self.name}


#: Touch models by name (``explore(..., touch="point")``).
TOUCH_MODELS: dict[str, type] = {"point": PointTouch}


def touch_model(touch) -> object:
    """A touch model from its name or itself (any object with ``observations(result, contacts, policy, step)``).

    Raises:
        ValueError: an unknown name.
    """
    if touch is None:
        return PointTouch()
    if isinstance(touch, str):
        if touch not in TOUCH_MODELS:
            raise ValueError(f"touch: must be one of {sorted(TOUCH_MODELS)} or a touch model, got {touch!r}")
        return TOUCH_MODELS[touch]()
    if not callable(getattr(touch, "observations", None)):
        raise ValueError(f"touch: expected a name or an object with observations(result, contacts, policy, step), "
                         f"got {type(touch).__name__}")
    return touch
