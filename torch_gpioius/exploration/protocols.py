"""The contracts of the exploration's parts, each one method or a few: a toucher moves, a touch model turns what a
touch returned into observations, an evidence policy decides when to gather extra evidence and gathers it, and a
recorder observes. The loop (:mod:`torch_gpioius.exploration.loop`) calls these and nothing else; stop rules are in
:mod:`torch_gpioius.exploration.stopping`.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["Toucher", "TouchModel", "TouchModelBase", "EvidencePolicy", "Recorder"]


@runtime_checkable
class Toucher(Protocol):
    """Force-guarded motion of the fingertip (:class:`torch_gpioius.exploration.contact.ContactController` on a robot
    arm, a geometric one in the 2-D world). Each method returns a
    :class:`torch_gpioius.exploration.contact.ContactResult`.

    * ``approach(direction, max_travel)``: move along ``direction`` `(d,)` until contact, at most ``max_travel`` [m];
    * ``slide(step, normal)``: execute a planned step `(d,)` [m] along the surface, keeping contact;
    * ``lift(direction, *, step, until_force_below, extra, max_distance, inside)``: move away along ``direction``
      until the force falls below ``until_force_below`` [N] (and ``inside(p)`` is False), then ``extra`` [m] more.
    """

    def approach(self, direction, max_travel: float = ...) -> Any: ...

    def slide(self, step, normal) -> Any: ...

    def lift(self, direction, *, step: float = ..., until_force_below: float = ..., extra: float = ...,
             max_distance: float = ..., inside=None) -> Any: ...


@runtime_checkable
class TouchModel(Protocol):
    """What one touch tells (:mod:`torch_gpioius.exploration.touch`): ``observations(result, contacts, policy, step)``
    turns a :class:`~torch_gpioius.exploration.contact.ContactResult` into an
    :class:`~torch_gpioius.exploration.observations.Observations` batch of the inner task; ``contacts`` `(k, d)` are
    all contacts so far, the new one last (free space keeps a margin from each)."""

    name: str

    def observations(self, result, contacts: np.ndarray, policy, step: int) -> Any: ...


class TouchModelBase:
    """The touch-model contract with its defaults: subclass it and write :meth:`observations`; override the rest where
    a touch needs it (the exploration calls each, and never asks whether a touch has it).

    Attributes:
        name: the touch's name in logs and records.
        inference: the engine a visual-tactile model uses with this touch ("auto"; a patch's: "batched").
        retraction_margin: free space closer than this to a new contact is retracted [m]; None: the labels'
            ``free_space_margin``.
    """

    name: str = "custom"
    inference: str = "auto"
    retraction_margin: float | None = None

    def observations(self, result, contacts: np.ndarray, policy, step: int) -> Any:
        """The :class:`~torch_gpioius.exploration.observations.Observations` batch of one touch (see
        :class:`TouchModel`)."""
        raise NotImplementedError(f"{type(self).__name__}.observations")

    def bind(self, hardware) -> None:
        """Take what the touch reads from a run's hardware (a pad) before the run starts; nothing by default."""

    def select(self, model, obs):
        """The rows of a batch worth adding to ``model`` (a patch's informative points); all by default."""
        return obs

    def fit_options(self) -> dict:
        """Options for K_t's fit after this touch (the model takes those its ``FIT_OPTIONS`` names); none by
        default."""
        return {}

    def footprint(self) -> dict:
        """Arrays a log keeps of the last touch (a pad's pose and size); none by default."""
        return {}

    def describe(self) -> dict:
        return {"touch": self.name}


@runtime_checkable
class EvidencePolicy(Protocol):
    """Evidence gathered on purpose, beyond the paper's sliding (:mod:`torch_gpioius.exploration.evidence`).

    * ``due(state)``: whether to act after the current step (reads the public
      :class:`~torch_gpioius.exploration.state.ExplorationState` and its model; changes nothing);
    * ``gather(state, toucher)``: move with the toucher and return an
      :class:`~torch_gpioius.exploration.evidence.Evidence` (the loop turns it into observations and updates the
      state), or None when the robot refused;
    * ``describe()``: JSON-able settings for the log header.
    """

    name: str

    def due(self, state) -> bool: ...

    def gather(self, state, toucher) -> Any: ...

    def describe(self) -> dict: ...


class EvidencePolicyBase:
    """A base for evidence policies that declares the whole contract the exploration calls, with defaults:

    * ``name``: the policy's name in logs and run files (default: the class name);
    * ``needs_vision``: whether it reads the outer task (a camera's): True refuses it in touch-only modes;
    * ``due(state)`` and ``gather(state, toucher)``: see :class:`EvidencePolicy` (no default);
    * ``for_run(dim=, bounds=, budget=)``: the policy fitted to one run's range and travel budget (default: itself);
    * ``describe()``: JSON-able settings for the log header (default: its name).

    ``explore(evidence=obj)`` takes any object with ``due`` and ``gather``; one that does not subclass this base gets
    these defaults (:func:`~torch_gpioius.exploration.policies.evidence_policy`).
    """

    name: str = "EvidencePolicyBase"
    needs_vision: bool = True

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if "name" not in cls.__dict__:          # a subclass without its own name is named by its class
            cls.name = cls.__name__

    def due(self, state) -> bool:
        raise NotImplementedError

    def gather(self, state, toucher) -> Any:
        raise NotImplementedError

    def for_run(self, *, dim: int, bounds=None, budget: float | None = None) -> "EvidencePolicyBase":
        return self

    def describe(self) -> dict:
        return {"name": self.name}


class Recorder:
    """Base class of the exploration's observers: crash-safe logs, ground-truth metrics, intervals, progress, or a
    user's own. Every hook is optional; recorders run in order, so one that measures (and fills the record) comes
    before one that writes it.

    * ``start(run, state)``: once, after the first contact (record 0 is in ``state.records``), or on resume;
    * ``step(run, state, record)``: after each step (the record is ``state.records[-1]``);
    * ``end(run, state)``: once, when the run has stopped (``state.terminated`` says why).

    ``run`` is the :class:`~torch_gpioius.exploration.config.Run`: the world, its hardware and the settings.
    """

    def start(self, run, state) -> None:
        pass

    def step(self, run, state, record) -> None:
        pass

    def end(self, run, state) -> None:
        pass
