"""The evidence policies by name: ``explore(..., evidence="taps")`` (:class:`~torch_gpioius.exploration.evidence.
TapPolicy`) and ``evidence="reach"`` (:class:`~torch_gpioius.exploration.reach.ReachPolicy`), and a study's modes
``visual-tactile+taps``. A module of its own so that each policy's module imports only the
:class:`~torch_gpioius.exploration.evidence.Evidence` it returns."""

from __future__ import annotations

from dataclasses import dataclass

from ..core.registry import Entry, Registry
from .evidence import TapPolicy
from .protocols import EvidencePolicyBase
from .reach import ReachPolicy

__all__ = ["EVIDENCE_POLICIES", "PolicyEntry", "register_evidence_policy", "evidence_policy"]


@dataclass
class PolicyEntry(Entry):
    """A registered evidence policy.

    Attributes:
        modes: the exploration modes it serves ("visual-tactile", "tactile", "local"): a study runs
            ``MODE+NAME`` for these (taps read the outer estimate, so touch alone cannot tap).
    """

    modes: tuple = ("visual-tactile", "tactile")


#: Evidence policies by name (``explore(..., evidence="taps")``, ``gpioius study --modes visual-tactile+taps``).
EVIDENCE_POLICIES: Registry[type] = Registry("evidence policy", entry_type=PolicyEntry)


def register_evidence_policy(name: str, cls: type, *, modes=("visual-tactile", "tactile"), aliases=(),
                             description: str = "") -> type:
    """Register an evidence policy class (built without arguments; its objects have ``due(state)`` and
    ``gather(state, toucher)``) under ``name``: ``explore(..., evidence=name)`` and a study's ``MODE+NAME`` modes then
    know it. Returns ``cls``.

    Raises:
        ValueError: ``cls`` lacks ``due`` or ``gather``, an unknown mode, or the name is taken by another class.
    """
    if not (isinstance(cls, type) and callable(getattr(cls, "due", None)) and callable(getattr(cls, "gather", None))):
        raise ValueError(f"register_evidence_policy: {cls!r} is not a class with due(state) and gather(state, toucher)")
    bad = [m for m in modes if m not in ("visual-tactile", "tactile", "local")]
    if bad or not modes:
        raise ValueError(f"register_evidence_policy: modes must be among visual-tactile, tactile and local, got "
                         f"{tuple(modes)!r}")
    EVIDENCE_POLICIES.register(name, cls, modes=tuple(modes), aliases=aliases, description=description)
    return cls


register_evidence_policy("taps", TapPolicy, modes=("visual-tactile", "local"),
                         description="lift off and come back down where the cover may stand off the body")
register_evidence_policy("reach", ReachPolicy, modes=("visual-tactile", "tactile"),
                         description="move to the most uncertain reachable place when the slide stalls")


def evidence_policy(evidence) -> EvidencePolicyBase | None:
    """The policy ``evidence`` names (None: the paper's exploration), ``evidence`` itself if it subclasses
    :class:`~torch_gpioius.exploration.protocols.EvidencePolicyBase`, or any object with ``due(state)`` and
    ``gather(state, toucher)`` with the base's defaults for the rest (the one place that looks at what an object has:
    the exploration then calls the contract's methods).

    Raises:
        ValueError: an unknown name or an object without those methods.
    """
    if evidence is None:
        return None
    if isinstance(evidence, str):
        if evidence not in EVIDENCE_POLICIES:
            raise ValueError(f"evidence: must be None, one of {EVIDENCE_POLICIES.choices()} or a policy object, got "
                             f"{evidence!r}")
        return evidence_policy(EVIDENCE_POLICIES.make(evidence))
    if isinstance(evidence, EvidencePolicyBase):
        return evidence
    if not (callable(getattr(evidence, "due", None)) and callable(getattr(evidence, "gather", None))):
        raise ValueError(f"evidence: a policy needs due(state) and gather(state, toucher), got "
                         f"{type(evidence).__name__}")
    return _DueAndGather(evidence)


class _DueAndGather(EvidencePolicyBase):
    """A policy given as an object with ``due`` and ``gather`` (and, optionally, ``name``, ``needs_vision``,
    ``for_run`` and ``describe``), with the base's defaults where it has none."""

    def __init__(self, policy) -> None:
        self.policy = policy
        self.name = str(getattr(policy, "name", type(policy).__name__))
        self.needs_vision = bool(getattr(policy, "needs_vision", True))

    def due(self, state) -> bool:
        return self.policy.due(state)

    def gather(self, state, toucher):
        return self.policy.gather(state, toucher)

    def for_run(self, *, dim: int, bounds=None, budget: float | None = None) -> EvidencePolicyBase:
        for_run = getattr(self.policy, "for_run", None)
        return self if for_run is None else evidence_policy(for_run(dim=dim, bounds=bounds, budget=budget))

    def describe(self) -> dict:
        describe = getattr(self.policy, "describe", None)
        return describe() if callable(describe) else super().describe()
