"""Plain progress lines (outside a terminal): what is done, what just finished, and no long silence."""

import io

from torch_gpioius.core import progress as _progress


def test_lines_say_what_is_done_and_name_the_run_that_just_finished(monkeypatch):
    """Issue 35, item 9: "25 % (object A, ...)" read as if A were running; it had just finished."""
    out = io.StringIO()
    bar = _progress._Lines(4, "2-D study", stream=out)
    for name in ("A", "B"):
        bar.set_postfix_str(f"object {name}, visual-tactile")      # set before the run, as the studies do
        bar.update(1)                                              # ... and counted after it
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("2-D study: 25 % done (last: object A, visual-tactile), ")
    assert lines[1].startswith("2-D study: 50 % done (last: object B, visual-tactile), ")


def test_a_long_stretch_between_quarters_still_prints(monkeypatch):
    """Stretches of 10-20 s printed nothing; a line comes at the first update after ``quiet`` seconds."""
    clock = iter([0.0, 3.0, 12.0, 13.0, 30.0, 30.0])
    monkeypatch.setattr(_progress.time, "perf_counter", lambda: next(clock))
    out = io.StringIO()
    bar = _progress._Lines(100, "object H, visual-tactile: travel [cm]", stream=out, quiet=10.0)   # t = 0
    bar.update(1)                                     # t = 3: quiet
    bar.update(2)                                     # t = 12: 12 s without a line -> one, then t = 13 stamps it
    bar.update(1)                                     # t = 30: again
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("object H, visual-tactile: travel [cm]: 3 % done") and len(lines) == 2
