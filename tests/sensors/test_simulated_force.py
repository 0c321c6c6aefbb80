"""Simulated force sensor: penalty forces, sensor-frame rotation, noise, drift, dropouts, faults."""

import math

import pytest
import torch

from torch_gpioius.sensors import (ForceFieldContact, SensorDisconnected, SimulatedForceSensor, SphereSDF)


def pose_at(p, R=None):
    T = torch.eye(4, dtype=torch.float64)
    T[:3, 3] = torch.as_tensor(p, dtype=torch.float64)
    if R is not None:
        T[:3, :3] = R
    return T


def test_penalty_force_inner_and_cover():
    c = torch.zeros(3, dtype=torch.float64)
    world = ForceFieldContact(SphereSDF(c, 0.1), SphereSDF(c, 0.12), k_inner=1000.0, k_cover=10.0)
    f_cover = world(torch.tensor([0.0, 0.0, 0.11], dtype=torch.float64))     # 1 cm into the cover only
    assert torch.allclose(f_cover, torch.tensor([0.0, 0.0, 0.1], dtype=torch.float64))
    f = world(torch.tensor([0.0, 0.0, 0.097], dtype=torch.float64))        # 3 mm into the inner sphere
    assert torch.allclose(f, torch.tensor([0.0, 0.0, 3.0 + 0.23], dtype=torch.float64))
    assert float(world(torch.tensor([0.0, 0.0, 0.2], dtype=torch.float64)).norm()) == 0.0


def test_reading_is_in_the_sensor_frame():
    world = ForceFieldContact(SphereSDF(torch.zeros(3, dtype=torch.float64), 0.1))
    a = math.pi / 2
    Rz = torch.tensor([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]], dtype=torch.float64)
    s = SimulatedForceSensor(world, lambda: pose_at([0.098, 0.0, 0.0], Rz))
    r = s.read()                      # 2 N along base +x = sensor -y for a tool rotated +90 deg about z
    assert torch.allclose(r.force, torch.tensor([0.0, -2.0, 0.0], dtype=torch.float64), atol=1e-12)
    assert r.ok and r.counter == 1


def test_noise_drift_and_tare():
    world = ForceFieldContact(SphereSDF(torch.zeros(3, dtype=torch.float64), 0.1))
    t = [0.0]
    s = SimulatedForceSensor(world, lambda: pose_at([1.0, 0.0, 0.0]), clock=lambda: t[0], drift=(0.0, 0.0, 0.5))
    t[0] = 2.0
    assert torch.allclose(s.read().force, torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64))
    s.tare()
    t[0] = 3.0
    assert torch.allclose(s.read().force, torch.tensor([0.0, 0.0, 0.5], dtype=torch.float64))
    noisy = SimulatedForceSensor(world, lambda: pose_at([1.0, 0.0, 0.0]), noise_std=0.1, seed=3)
    samples = torch.stack([noisy.read().force for _ in range(2000)])
    assert abs(float(samples.std()) - 0.1) < 0.01 and abs(float(samples.mean())) < 0.01


def test_dropouts_repeat_the_previous_sample_and_disconnect_persists():
    world = ForceFieldContact(SphereSDF(torch.zeros(3, dtype=torch.float64), 0.1))
    s = SimulatedForceSensor(world, lambda: pose_at([1.0, 0.0, 0.0]), dropout=0.5, seed=1)
    counters = [s.read().counter for _ in range(200)]
    repeats = sum(a == b for a, b in zip(counters, counters[1:]))
    assert 60 < repeats < 140
    s2 = SimulatedForceSensor(world, lambda: pose_at([1.0, 0.0, 0.0]), faults={1: "disconnect"})
    s2.read()
    for _ in range(3):
        with pytest.raises(SensorDisconnected):
            s2.read()
    with pytest.raises(ValueError, match="unknown fault"):
        SimulatedForceSensor(world, lambda: pose_at([1.0, 0.0, 0.0]), faults={0: "melt"})


def test_bounding_boxes_skip_only_forces_that_are_zero():
    """With each surface's box given, a fingertip outside it is not looked up; every force is the one computed
    without the boxes, to the bit (points inside, between the surfaces, beside and far from the body)."""
    import trimesh

    from torch_gpioius.sim.shapes3d import MeshSDF

    inner = trimesh.creation.icosphere(subdivisions=2, radius=0.05)
    outer = trimesh.creation.icosphere(subdivisions=2, radius=0.06)
    plain = ForceFieldContact(MeshSDF(inner), MeshSDF(outer))
    boxed = ForceFieldContact(MeshSDF(inner), MeshSDF(outer), inner_bounds=inner.bounds, outer_bounds=outer.bounds)
    g = torch.Generator().manual_seed(0)
    points = (torch.rand(300, 3, generator=g, dtype=torch.float64) - 0.5) * 0.2
    nonzero = 0
    for p in points:
        a, b = plain(p), boxed(p)
        assert torch.equal(a, b)
        nonzero += int(float(a.norm()) > 0)
    assert nonzero > 5                           # some points do press into a surface


def test_bad_bounding_boxes_are_refused():
    sphere = SphereSDF(torch.zeros(3, dtype=torch.float64), 0.1)
    with pytest.raises(ValueError, match="inner_bounds"):
        ForceFieldContact(sphere, inner_bounds=[[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="outer_bounds"):
        ForceFieldContact(sphere, sphere, outer_bounds=[[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]])
