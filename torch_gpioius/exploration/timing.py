"""Where an exploration's wall time goes: the method, the camera, the contact and the measuring.

:class:`PartClock` times, for the duration of one run, the calls that do each part by wrapping the methods of that
run's own objects (never their classes: another run in the same process is not counted):

* **camera**: ``hardware.camera.capture`` (every simulated view's ray casting, or a real camera's frame);
* **contact**: the contact controller's guarded motions (``approach``, ``slide``, ``lift``: the force field or the
  physics, the UR5's kinematics, the sensor) and a tactile pad's reads;
* **measuring**: ``world.measure`` (the estimate against the true body: the converged ruler's mesh and metrics);
* **method**: the rest of the run, what the method itself does (planning steps, labelling, the model's updates and
  K_t's re-learning, the similarity's interval, the log).

A part calling itself (a slide made of guarded sub-steps) is counted once. ``benchmarks/run_cost.py`` prints the
split of a run; every study run records it (``gpioius study``'s ``time_*`` columns).
"""

from __future__ import annotations

import time
from collections import defaultdict

__all__ = ["PartClock", "PARTS"]

#: The parts of a run besides the method, in the order records and tables carry them.
PARTS = ("camera", "contact", "measuring")


class PartClock:
    """Times the parts of one run (see the module docstring); a context manager around the run.

    Args:
        world: the run's world (its ``measure`` is the measuring).
        hardware: the run's :class:`~torch_gpioius.exploration.world.Hardware`.

    Attributes:
        spent: ``{part: seconds}`` once the run has ended (and ``"total"``, ``"method"``).
    """

    def __init__(self, world, hardware) -> None:
        self._targets = [(world, "measure", "measuring"), (hardware.camera, "capture", "camera")]
        self._targets += [(hardware.controller, name, "contact") for name in ("approach", "slide", "lift")]
        if getattr(hardware, "tactile", None) is not None:
            self._targets += [(hardware.tactile, name, "contact") for name in ("read", "reading")]
        self.spent: dict[str, float] = defaultdict(float)
        self._depth: dict[str, int] = defaultdict(int)
        self._wrapped: list[tuple[object, str, bool, object]] = []

    def __enter__(self) -> "PartClock":
        for obj, name, part in self._targets:
            if obj is None or not callable(getattr(obj, name, None)):
                continue
            own = name in getattr(obj, "__dict__", {})
            original = getattr(obj, name)
            try:
                setattr(obj, name, self._timed(original, part))
            except (AttributeError, TypeError):          # a slotted or frozen object: its part is not split out
                continue
            self._wrapped.append((obj, name, own, original))
        self._t0 = time.perf_counter()
        return self

    def _timed(self, original, part: str):
        def timed(*args, **kwargs):
            self._depth[part] += 1
            t0 = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                self._depth[part] -= 1
                if self._depth[part] == 0:
                    self.spent[part] += time.perf_counter() - t0
        return timed

    def __exit__(self, *exc: object) -> None:
        total = time.perf_counter() - self._t0
        for obj, name, own, original in reversed(self._wrapped):
            if own:
                setattr(obj, name, original)
            else:
                delattr(obj, name)                         # the class's method shows through again
        self._wrapped.clear()
        self.spent["total"] = total
        self.spent["method"] = total - sum(self.spent.get(p, 0.0) for p in PARTS)

    def split(self) -> dict[str, float]:
        """``{"method", "camera", "contact", "measuring", "total"}`` [s]."""
        return {k: float(self.spent.get(k, 0.0)) for k in ("method", *PARTS, "total")}
