"""The exploration's built-in observers: the ground-truth metrics, the correlation's profile interval, progress.

They run in that order before any recorder a caller adds (a log, a user's own), so what they measure is in the
record before it is written. Each is a :class:`~torch_gpioius.exploration.protocols.Recorder`.
"""

from __future__ import annotations

import math
import warnings

from ..core.progress import progress as progress_reporter
from ..geometry.metrics import SHAPE_METRICS
from .protocols import Recorder

__all__ = ["MetricsRecorder", "IntervalRecorder", "ProgressRecorder", "NoEstimateWarning", "REPORT_FRACTIONS"]


class NoEstimateWarning(RuntimeWarning):
    """A run ended with no estimated inner surface to judge: {mu_in = 0} has no closed curve (2-D) or no surface
    inside the range (3-D). Its Hausdorff distance is NaN, its figures are empty, and a study counts it as failed
    ("no estimate")."""


#: Fractions of the travel budget at which studies report the metrics (10, 25, 50 %): a budgeted run measures at the
#: first step that reaches each, so "H at 10 %" is taken there, not at the next ``metrics_every`` step (which a
#: long re-approach could put at 30 % of the budget).
REPORT_FRACTIONS = (0.10, 0.25, 0.50)


class MetricsRecorder(Recorder):
    """Ground-truth metrics (eq. 23-24) where the world knows the truth, every ``config.metrics_every`` steps and
    before exploring (None: neither, the schedule alone), at the first step that reaches each of
    :data:`REPORT_FRACTIONS` of a travel budget, at a step a stop rule ended, and at the end if the last record has
    none. Sets ``state.centre`` and ``state.surface``
    from each measurement (a stop rule may read the centre)."""

    def _measure(self, run, state, record) -> None:
        m = run.world.measure(state.model, state.contacts_array(), run.config.metrics_resolution)
        state.centre, state.surface = m.centre, m.surface
        record.hausdorff, record.hausdorff_touched, record.uncertainty = (float(m.hausdorff),
                                                                          float(m.hausdorff_touched),
                                                                          float(m.uncertainty))
        record.estimate = math.nan if m.estimate is None else float(m.estimate)
        for name in SHAPE_METRICS:                       # the field's metrics (3-D worlds); NaN where not computed
            setattr(record, name, float(m.shape.get(name, math.nan)))

    def start(self, run, state) -> None:
        # the schedule alone (metrics_every None) measures what studies report, the fractions and the end: the state
        # before exploring is not one of them
        if not run.resumed and run.config.metrics_every is not None:
            self._measure(run, state, state.records[0])

    def step(self, run, state, record) -> None:
        every = run.config.metrics_every                    # None: the schedule alone
        if (every is not None and record.step % every == 0) or record.final or self._milestone(run, state, record):
            self._measure(run, state, record)

    @staticmethod
    def _milestone(run, state, record) -> bool:
        """Whether this step is the first to reach one of :data:`REPORT_FRACTIONS` of the travel budget."""
        budget = run.config.budget
        if budget is None or len(state.records) < 2:
            return False
        before = state.records[-2].travel
        return any(before < f * budget <= record.travel for f in REPORT_FRACTIONS)

    def end(self, run, state) -> None:
        last = state.records[-1]
        if len(state.records) > 1 and math.isnan(last.estimate) and math.isnan(last.hausdorff):
            self._measure(run, state, last)                           # the final estimate is always measured
        if last.estimate == 0.0:
            warnings.warn(f"explore: {run.world.name or type(run.world).__name__} ({run.config.mode}) ended at step "
                          f"{last.step} with no estimated inner surface to judge (mu_in = 0 has "
                          f"{'no closed curve' if run.dim == 2 else 'no surface inside the range'}): its Hausdorff "
                          "distance is NaN and its figures are empty", NoEstimateWarning, stacklevel=2)


class IntervalRecorder(Recorder):
    """The task correlation's 95 % profile-likelihood interval every ``config.interval_every`` steps, at a step a
    stop rule ended, and at the end (visual-tactile models with one K_t; never when ``interval_every`` is None)."""

    @staticmethod
    def _applies(run, state) -> bool:
        m = state.model
        return (run.config.interval_every is not None and hasattr(m, "similarity_interval")
                and not hasattr(m, "region_correlations"))

    def start(self, run, state) -> None:
        if not run.resumed:
            self.step(run, state, state.records[0])

    def step(self, run, state, record) -> None:
        if self._applies(run, state) and (record.step % run.config.interval_every == 0 or record.final):
            record.correlation_interval = tuple(float(v) for v in state.model.similarity_interval(kind="correlation"))

    def end(self, run, state) -> None:
        last = state.records[-1]
        if self._applies(run, state) and state.records and math.isnan(last.correlation_interval[0]):
            last.correlation_interval = tuple(float(v) for v in state.model.similarity_interval(kind="correlation"))


class ProgressRecorder(Recorder):
    """A progress bar on a terminal (plain lines otherwise): centimetres of the travel budget, or steps."""

    def __init__(self, enabled: bool = False) -> None:
        self.enabled = enabled
        self._bar = None

    def _done(self, run, state) -> int:
        budget = run.config.budget
        return min(round(state.travel * 100), round(budget * 100)) if budget else state.steps

    def start(self, run, state) -> None:
        budget = run.config.budget
        # "object H, visual-tactile: travel [cm]" (the old "H visual-tactile [cm]" read like a Hausdorff distance)
        what = "travel [cm]" if budget else "steps"
        self._bar = progress_reporter(round(budget * 100) if budget else run.config.max_steps,
                                      f"object {run.world.name or 'world'}, {run.config.mode}: {what}", self.enabled)
        self._bar.update(self._done(run, state))

    def step(self, run, state, record) -> None:
        self._bar.update(self._done(run, state) - self._bar.n)

    def end(self, run, state) -> None:
        self._bar.close()
