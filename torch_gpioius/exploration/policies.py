"""The evidence policies by name: ``explore(..., evidence="taps")`` (:class:`~torch_gpioius.exploration.evidence.
TapPolicy`) and ``evidence="reach"`` (:class:`~torch_gpioius.exploration.reach.ReachPolicy`). A module of its own so
that each policy's module imports only the :class:`~torch_gpioius.exploration.evidence.Evidence` it returns."""

from __future__ import annotations

from .evidence import TapPolicy
from .reach import ReachPolicy

__all__ = ["EVIDENCE_POLICIES", "evidence_policy"]

#: Evidence policies by their shorthand (``explore(..., evidence="taps")``, ``evidence="reach"``).
EVIDENCE_POLICIES: dict[str, type] = {"taps": TapPolicy, "reach": ReachPolicy}


def evidence_policy(evidence) -> object | None:
    """The policy ``evidence`` names (None: the paper's exploration), or ``evidence`` itself if it is a policy
    (any object with ``due(state)`` and ``gather(state, toucher)``).

    Raises:
        ValueError: an unknown name or an object without those methods.
    """
    if evidence is None:
        return None
    if isinstance(evidence, str):
        if evidence not in EVIDENCE_POLICIES:
            raise ValueError(f"evidence: must be None, one of {sorted(EVIDENCE_POLICIES)} or a policy object, got "
                             f"{evidence!r}")
        return EVIDENCE_POLICIES[evidence]()
    if not (callable(getattr(evidence, "due", None)) and callable(getattr(evidence, "gather", None))):
        raise ValueError(f"evidence: a policy needs due(state) and gather(state, toucher), got "
                         f"{type(evidence).__name__}")
    return evidence
