"""No run stalls: the no-progress rule against hand-made contact histories, and on a real stall (object C approached
from the side where cover and body coincide, whose plain run sits in a corner from step 111 on)."""

from types import SimpleNamespace

import numpy as np
import pytest

import torch_gpioius as tg
from torch_gpioius.exploration.recovery import NoProgress


def _state(contacts, steps=None, last_recovery=0):
    contacts = [np.asarray(c, dtype=float) for c in contacts]
    return SimpleNamespace(contacts=contacts, steps=len(contacts) - 1 if steps is None else steps,
                           last_recovery=last_recovery)


def test_the_rule_judges_only_a_full_window_and_measures_distance_from_the_last_contact():
    rule = NoProgress(window=4, min_progress=0.01)
    still = [(0.0, 0.0)] * 3
    assert rule.stalled(_state(still)) is None                               # window not yet full
    assert rule.stalled(_state([(0.0, 0.0)] * 6)) is True
    assert rule.stalled(_state([(0.0, 0.0)] * 6, last_recovery=3)) is None    # a recovery restarts the window
    # sliding back and forth 4 mm around one place is no progress; one step 1.1 cm away within the window is
    back_and_forth = [(0.004 * (i % 2), 0.0) for i in range(6)]
    assert rule.stalled(_state(back_and_forth)) is True
    moved = [(0.0, 0.0), (0.011, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0)]
    assert rule.stalled(_state(moved)) is False
    older = [(0.011, 0.0)] + [(0.0, 0.0)] * 5                                # outside the last 4 steps
    assert rule.stalled(_state(older)) is True


@pytest.mark.parametrize("kw", [dict(window=1), dict(window=2.5), dict(max_recoveries=-1), dict(min_progress=0.0),
                                dict(lift=float("nan")), dict(max_lift=2.0), dict(window=True)])
def test_bad_settings_are_refused(kw):
    with pytest.raises(ValueError, match="NoProgress"):
        NoProgress(**kw)


def _longest_stay(contacts, radius=0.01):
    """The most consecutive steps the contact stayed within ``radius`` of where such a stay ended."""
    c = np.asarray(contacts)
    best = 0
    for end in range(len(c)):
        k = 0
        while end - k - 1 >= 0 and np.linalg.norm(c[end - k - 1] - c[end]) < radius:
            k += 1
        best = max(best, k)
    return best


def test_a_stalled_run_recovers_and_its_recovery_is_paid_for(c_from_the_left, c_left_without_recovery):
    stuck = c_left_without_recovery
    assert _longest_stay(stuck.contacts) >= 25                  # the corner holds it from step 111 to the end
    rule = NoProgress()
    freed = tg.explore(c_from_the_left, max_steps=140, stall=rule)
    assert freed.recoveries[-1] >= 1
    # with the rule no stay is longer than its window, times the recoveries it may try
    assert _longest_stay(freed.contacts) <= rule.window * (rule.max_recoveries + 1)
    # a recovery counts as a step of the budget, and its lift and approach as travel
    assert freed.n_steps - 1 + freed.recoveries[-1] + freed.taps[-1] <= 140
    k = int(np.argmax(np.diff(freed.recoveries) > 0)) + 1               # the record of the first recovery
    assert freed.travel[k] - freed.travel[k - 1] >= 2 * rule.lift          # lifted at least `lift`, and came back
    # the recovery lifts along the measured normal and comes back: it presses no deeper into the body than sliding
    deepest = c_from_the_left.true_distance(np.asarray(stuck.path)).min()
    assert c_from_the_left.true_distance(np.asarray(freed.path)).min() >= deepest - 1e-9
