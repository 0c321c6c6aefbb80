"""The world contract's tests: what the exploration loop, the studies and the logs rely on of a
:class:`~torch_gpioius.exploration.world.World` (a world's test file subclasses :class:`WorldContract`, the project's
own and a user's alike).

Checked: the declared attributes (``dim``, a ``start`` and a unit ``direction`` of that dimension, a registered
``kind`` whose entry builds this class), ``defaults`` as :class:`~torch_gpioius.exploration.world.ExplorationDefaults`,
``hardware()`` as a fresh :class:`~torch_gpioius.exploration.world.Hardware` each call, the seeded perturbations
(seed 0 the world itself, a seed the same world twice, the geometry's fingerprint unchanged), the log header
(``describe()`` JSON-able, with the kind), ``snapshot``/``restore`` round-tripping on fresh hardware, and a short
exploration that reaches the body and records contacts of the world's dimension inside its penalty's range.
"""

from __future__ import annotations

import json

import numpy as np

__all__ = ["WorldContract"]


class WorldContract:
    """pytest checks of the world contract: subclass it in a test file as ``class TestMyWorld(WorldContract)`` with
    ``make()`` returning the world under test; pytest runs each ``test_*`` method. ``steps`` sets the short
    exploration's length (a few planning steps: the contract is about the interfaces, not the accuracy).

    Example:
        >>> class TestBallWorld(WorldContract):
        ...     def make(self):
        ...         return BallWorld()
    """

    steps = 3

    def make(self):
        raise NotImplementedError

    def test_declares_its_dimension_start_and_direction(self):
        world = self.make()
        assert world.dim in (2, 3)
        start, direction = np.asarray(world.start, float), np.asarray(world.direction, float)
        assert start.shape == (world.dim,) and direction.shape == (world.dim,)
        assert np.isfinite(start).all() and abs(np.linalg.norm(direction) - 1.0) < 1e-9

    def test_is_registered_by_its_kind(self):
        from ..exploration.registry import world_entry

        world = self.make()
        assert world.kind, f"{type(world).__name__} is not registered (register_world sets its kind)"
        entry = world_entry(world.kind)
        assert isinstance(world, entry.cls) and entry.dimension == world.dim

    def test_defaults_and_hardware(self):
        from ..exploration.world import ExplorationDefaults, Hardware

        world = self.make()
        assert isinstance(world.defaults, ExplorationDefaults)
        first, second = world.hardware(), world.hardware()
        assert isinstance(first, Hardware) and isinstance(second, Hardware)
        assert first.robot is not second.robot, "hardware() must return fresh hardware each call"
        for part in ("robot", "sensor", "camera", "controller"):
            assert getattr(first, part) is not None, f"hardware().{part} is None"

    def test_seeds_perturb_reproducibly_and_keep_the_geometry(self):
        world = self.make()
        assert world.perturbed(0) is world or world.perturbed(0).fingerprint() == world.fingerprint()
        try:
            a, b = world.perturbed(3), world.perturbed(3)
        except NotImplementedError:
            return                                   # a world without seeded perturbations (a real robot)
        assert np.array_equal(np.asarray(a.start), np.asarray(b.start))
        assert np.array_equal(np.asarray(a.direction), np.asarray(b.direction))
        assert a.dim == world.dim and a.kind == world.kind

    def test_describes_itself_for_a_log_header(self):
        world = self.make()
        header = world.describe()
        json.dumps(header)
        assert header["world"] == world.kind and header["dim"] == world.dim
        assert isinstance(world.fingerprint(), str) and world.fingerprint() == self.make().fingerprint()

    def test_a_snapshot_restores_on_fresh_hardware(self):
        world = self.make()
        hw = world.hardware()
        state = world.snapshot(hw)
        assert all(isinstance(v, np.ndarray) for v in state.values())
        world.restore(world.hardware(), state)

    def test_a_short_exploration_touches_the_body(self):
        import torch_gpioius as tg

        world = self.make()
        trace = tg.explore(world, max_steps=self.steps, metrics_every=10_000)
        contacts = np.asarray(trace.contacts)
        assert contacts.ndim == 2 and contacts.shape[1] == world.dim and len(contacts) >= 1
        assert np.isfinite(contacts).all()
        distance = world.true_distance(contacts)
        if distance is not None:                      # a world that knows its body: the contacts lie on it
            assert np.abs(distance).max() < 0.02, f"contacts {np.abs(distance).max():.3f} m off the body"
