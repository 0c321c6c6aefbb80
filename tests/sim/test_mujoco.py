"""The MuJoCo world: the generated UR5 against the project's kinematics, physics sanity against independent
expectations (a fingertip pressed into cloth over a box, a settling cloth, a quiet sensor), the gate under every
command, determinism, and bad input."""

import math

import numpy as np
import pytest
import torch

mujoco = pytest.importorskip("mujoco")

import torch_gpioius as tg  # noqa: E402
from kinematics import UR5  # noqa: E402
from torch_gpioius.sim.mujoco import (MujocoInstability, MujocoScene, arm_primitives, mujoco_objects_3d,  # noqa: E402
                                      union_sdf, ur5_mjcf)
from torch_gpioius.sim.mujoco.primitives import as_primitives  # noqa: E402

BOX = [{"type": "box", "size": (0.06, 0.06, 0.06), "pos": (0.5, 0.0, 0.2)}]
BOX_RANGE = [[0.38, -0.12, 0.2], [0.62, 0.12, 0.36]]


def box_scene(cover="loose", seed=0, **kw):
    """A 12 cm box under a cloth cap built 3 cm off it that settles under gravity; the fingertip comes from above."""
    opts = dict(slack=0.03) if cover == "loose" else dict(gap=0.008)
    opts = dict(name="box", spacing=0.025, **opts)
    opts.update(kw)
    return MujocoScene.from_primitives(BOX, cover, start=(0.505, 0.004, 0.40), direction=(0, 0, -1), bounds=BOX_RANGE,
                                       seed=seed, base="cap", centre=(0.5, 0.0, 0.2), facing=(0, 0, 1),
                                       half_angle=80.0, **opts)


@pytest.fixture(scope="module")
def scene():
    return box_scene()


def test_the_generated_ur5_has_the_project_kinematics():
    body, act, sens = ur5_mjcf(tool_offset=(0.0, 0.0, 0.05))
    m = mujoco.MjModel.from_xml_string(f'<mujoco><compiler angle="radian" autolimits="true"/><worldbody>{body}'
                                       f'</worldbody><actuator>{act}</actuator></mujoco>')
    d = mujoco.MjData(m)
    ur5 = UR5(tool_offset=(0.0, 0.0, 0.05))
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = rng.uniform(-3.0, 3.0, 6)
        d.qpos[:6] = q
        mujoco.mj_forward(m, d)
        T = ur5.forward_kinematics(torch.tensor(q)).numpy()
        np.testing.assert_allclose(d.site("ft_site").xpos, T[:3, 3], atol=1e-12)
        np.testing.assert_allclose(d.site("ft_site").xmat.reshape(3, 3), T[:3, :3], atol=1e-12)
    # UR's published masses are carried (the cylinder inertias are ours)
    assert [round(float(m.body(f"link_{i}").mass[0]), 4) for i in range(1, 7)] == [3.7, 8.393, 2.275, 1.219, 1.219,
                                                                                  0.1879]


def test_a_dropped_cloth_settles_and_stays_finite(scene):
    v = scene.cover_vertices()
    assert np.isfinite(v).all()
    gap = union_sdf(scene.primitives, v)
    assert gap.min() > -1e-3                                   # rests on the box, does not sink into it
    assert np.median(gap[v[:, 2] > 0.26]) < 0.03               # it came down from 3 cm onto the box top
    hw = scene.hardware()
    physics = hw.robot.physics
    physics.step(100)
    assert physics.kinetic_energy() < 1e-3                     # at rest
    np.testing.assert_allclose(scene.cover_vertices(physics), v, atol=2e-3)


def test_the_sensor_reads_zero_within_its_noise_in_free_space(scene):
    hw = scene.hardware()
    readings = []
    for _ in range(60):
        hw.robot.physics.step(5)
        readings.append(hw.sensor.read().force.numpy())
    f = np.array(readings)
    assert np.abs(f.mean(axis=0)).max() < 4 * 0.02 / math.sqrt(len(f))      # unbiased after the tare
    assert np.allclose(f.std(axis=0), 0.02, rtol=0.4)                       # the OMD-20 noise model


def sheet_over_box(height=0.025, n=13, width=0.3):
    """A square cloth pinned along its edges ``height`` above the box top (a tent): the fingertip meets the cloth
    first and the box only after pushing the cloth down by ``height``."""
    from torch_gpioius.sim.mujoco.covers import CoverMesh
    g = np.linspace(-width / 2, width / 2, n)
    xx, yy = np.meshgrid(g, g, indexing="ij")
    verts = np.c_[0.5 + xx.ravel(), yy.ravel(), np.full(n * n, 0.26 + height)]
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            faces += [(a, b, c), (a, c, d)]
    edge = np.flatnonzero((np.abs(xx.ravel()) > width / 2 - 1e-9) | (np.abs(yy.ravel()) > width / 2 - 1e-9))
    cover = CoverMesh(verts, np.asarray(faces), edge, 2, "tight", 0.002, 5e4, 0.2, 1e-3, 0.02, 0.15)
    return MujocoScene(as_primitives(BOX), cover, (0.505, 0.004, 0.40), (0, 0, -1), BOX_RANGE, name="sheet")


def test_a_fingertip_pressed_into_cloth_over_a_box():
    """The force stays small while the fingertip pushes the cloth, then rises at the box; the recorded contact lies
    within 5 mm of the box; the cloth under the fingertip moved."""
    scene = sheet_over_box()
    hw = scene.hardware()
    before = scene.cover_vertices(hw.robot.physics)
    top = 0.26
    cloth_above = before[np.linalg.norm(before[:, :2] - scene.start[:2], axis=1) < 0.02][:, 2].max()
    assert cloth_above > top + 0.004                         # the settled cloth lies above the box here
    res = hw.controller.approach(torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64), max_travel=0.3)
    assert res.in_contact
    z = res.path[:, 2].numpy()
    force = res.forces.norm(dim=1).numpy()
    tip = scene.tip_radius
    pushing = (z - tip < cloth_above) & (z - tip > top + 0.006)     # below the settled cloth, well above the box
    assert pushing.any() and force[pushing].max() < 1.0             # the cloth gives way
    assert force[-1] >= 1.0
    box_distance = float(union_sdf(scene.primitives, res.contact.numpy()[None])[0])
    assert abs(box_distance) < 0.005
    after = scene.cover_vertices(hw.robot.physics)
    under = np.linalg.norm(before[:, :2] - res.contact.numpy()[:2], axis=1) < 0.03
    assert np.linalg.norm(after - before, axis=1)[under].max() > 0.002


def _assert_commands_within_gate(robot):
    gate, ur5 = robot.gate, robot.ur5
    lo, hi = ur5.lower + gate.joint_margin, ur5.upper - gate.joint_margin
    prev = torch.as_tensor(robot.log[0][1])
    for _, q, speed in robot.log[1:]:
        q = torch.as_tensor(q)
        assert bool(((q >= lo) & (q <= hi)).all())
        dq = (q - prev).abs()
        if float(dq.max()) > 0:
            assert bool((speed * dq / dq.max() <= gate.max_joint_speed * (1 + 1e-9)).all())
        s = torch.linspace(0, 1, 32, dtype=torch.float64)[:, None]
        tips = ur5.position(prev + s * (q - prev))
        assert bool(((tips >= gate.workspace_lower - 1e-9) & (tips <= gate.workspace_upper + 1e-9)).all())
        prev = q


def test_a_short_exploration_keeps_to_the_gate_and_repeats_with_its_seed(scene):
    made = []
    original = scene.hardware
    scene.hardware = lambda: made.append(original()) or made[-1]
    try:
        a = tg.explore(scene, mode="visual-tactile", max_travel=0.05, metrics_every=100)
        b = tg.explore(scene, mode="visual-tactile", max_travel=0.05, metrics_every=100)
    finally:
        del scene.hardware
    assert a.terminated == "travel" and a.n_steps >= 4
    np.testing.assert_array_equal(a.contacts, b.contacts)               # the same seed: the same trajectory
    for hw in made:
        _assert_commands_within_gate(hw.robot)
    assert np.isfinite(a.hausdorff[-1]) and np.isfinite(a.task_covariance[-1]).all()
    c = tg.explore(scene.perturbed(1), mode="visual-tactile", max_travel=0.03, metrics_every=100)
    assert np.abs(c.contacts[0] - a.contacts[0]).max() > 1e-4           # another seed starts elsewhere


def test_a_run_cut_after_a_step_resumes_to_the_same_end(scene, tmp_path):
    """The physics state (cloth, arm, fingertip springs, solver warm start), the sensor's noise generator and the
    clock are in every step record, so a run cut after step 3 resumes where it stopped. The resumed model is
    rebuilt from the logged observations and K_t (rounding-level differences, ~1e-14, from the incrementally
    updated engine of the uninterrupted run); the arm's rest detection is a threshold, so such a difference can
    change a settling by one time step from the first resumed step on: the logged contacts come back exactly and
    the rest agree within 1 mm (measured: 2e-4 m at the 8 ms step, one step of the settling arm; 5e-7 m at 4 ms)."""
    from torch_gpioius.io.datasets import read_records

    kw = dict(mode="visual-tactile", max_travel=0.06, metrics_every=100, progress=False)
    log = tmp_path / "run.gpioius"
    reference = tg.explore(scene, log=log, **kw)
    assert reference.n_steps > 5
    end = next(r.end for r in read_records(log) if r.kind == "step" and r.meta["step"] == 3)
    with open(log, "r+b") as f:
        f.truncate(end)
    resumed = tg.explore(scene, resume_from=log, **kw)
    assert resumed.terminated == reference.terminated
    n = min(len(resumed.contacts), len(reference.contacts))
    assert abs(len(resumed.contacts) - len(reference.contacts)) <= 1     # the travel budget may end a step apart
    np.testing.assert_allclose(resumed.contacts[:4], reference.contacts[:4], rtol=0, atol=1e-12)
    np.testing.assert_allclose(resumed.task_covariance[:4], reference.task_covariance[:4], rtol=1e-10, atol=0)
    np.testing.assert_allclose(resumed.contacts[:n], reference.contacts[:n], rtol=0, atol=1e-3)


# a square cup of 8 cm inside, 6 mm walls, 10 cm tall, open at the top: rays from its middle up through the opening
# never come within a tight cloth's 8 mm of it
CUP = [{"type": "box", "size": (0.046, 0.046, 0.003), "pos": (0.5, 0.0, 0.103)}] + [
    {"type": "box", "size": s, "pos": (0.5 + x, y, 0.153)}
    for s, x, y in (((0.003, 0.046, 0.05), 0.043, 0.0), ((0.003, 0.046, 0.05), -0.043, 0.0),
                    ((0.046, 0.003, 0.05), 0.0, 0.043), ((0.046, 0.003, 0.05), 0.0, -0.043))]
#: 9 mm above the cup's floor: along every ray up through the opening the closest point to the cup is this centre,
#: where the old wrap put each of them (as the mug's centre in its cavity did)
CUP_CENTRE = (0.5, 0.0, 0.115)


def cup_base(half_angle=100.0):
    from torch_gpioius.sim.mujoco.covers import cap_base
    return cap_base(CUP_CENTRE, (0.0, 0.0, 1.0), half_angle, 0.015, 0.07)


def test_a_cloth_over_an_open_cup_spans_its_opening_as_a_membrane():
    """The tight mug blew up at its first step: the rays through its opening never came within 8 mm of it, kept their
    closest point (the centre, for each of them) and made elements of no area. With the base's faces they lie as a
    membrane over the opening: each the mean of its neighbours (recomputed here), every vertex at least 8 mm off the
    cup, none two on one point; without the faces the old collapse (the fallback) is what the docstring says."""
    from torch_gpioius.sim.mujoco.covers import make_cover, shrink_wrap
    from torch_gpioius.sim.mujoco.primitives import union_sdf
    cup = as_primitives(CUP)
    origins, dirs, faces, _ = base = cup_base()
    collapsed = shrink_wrap(cup, origins, dirs, 0.008)
    spanned = shrink_wrap(cup, origins, dirs, 0.008, faces=faces)
    t_old, t = (np.linalg.norm(v - origins, axis=1) for v in (collapsed, spanned))
    free = union_sdf(cup, collapsed) > 0.008 + 1e-6      # the rays that leave through the opening
    assert np.allclose(collapsed[free], CUP_CENTRE)      # the fallback without the faces: all on the centre
    assert 3 <= free.sum() < len(t) // 2
    assert np.allclose(t[~free], t_old[~free])           # the rays that came within 8 mm are where they were
    nbrs = [set() for _ in t]
    for a, b, c in faces:
        nbrs[a] |= {b, c}
        nbrs[b] |= {a, c}
        nbrs[c] |= {a, b}
    for i in np.flatnonzero(free):
        assert t[i] == pytest.approx(np.mean([t[j] for j in nbrs[i]]), abs=1e-12)
    assert spanned[free, 2].min() > 0.203                # above the rim, not down in the cup
    assert union_sdf(cup, spanned).min() >= 0.008 - 1e-6
    gaps = np.linalg.norm(spanned[:, None] - spanned[None], axis=-1) + np.eye(len(t))
    assert gaps.min() > 0.005
    cover = make_cover(cup, "tight", base)
    assert np.allclose(cover.vertices, spanned)
    foam = make_cover(cup, "foam", base)                 # both layers spanned
    assert union_sdf(cup, foam.vertices).min() >= 0.008 - 1e-6


def test_a_cup_under_a_tight_cloth_settles_finite():
    """The tight mug's defect on a cup of primitives: its cloth was NaN at the first step (elements of no area)."""
    scene = MujocoScene.from_primitives(CUP, "tight", start=(0.5, 0.004, 0.32), direction=(0, 0, -1),
                                        bounds=[[0.42, -0.08, 0.1], [0.58, 0.08, 0.26]], base="cap",
                                        centre=CUP_CENTRE, facing=(0, 0, 1), half_angle=100.0, spacing=0.015,
                                        gap=0.008, name="cup")
    assert np.isfinite(scene.settled).all()
    verts = scene.cover_vertices()
    assert np.isfinite(verts).all() and verts[:, 2].max() < 0.26


def test_a_cover_with_elements_of_no_area_is_refused():
    """Where no ray of the base comes within the cover's distance (its centre far from the body), every vertex
    collapses onto the centre: refused by name, not a NaN at MuJoCo's first step."""
    from torch_gpioius.sim.mujoco.covers import cap_base, make_cover
    base = cap_base((0.5, 0.0, 0.6), (0.0, 0.0, 1.0), 60.0, 0.03, 0.1)
    with pytest.raises(ValueError, match="no area"):
        make_cover(as_primitives(BOX), "tight", base)


def test_bad_input_gets_named_errors():
    with pytest.raises(ValueError, match=r"inner\[0\].*between 1 mm and 2 m"):
        as_primitives([{"type": "capsule", "size": (0.05, -0.1), "pos": (0, 0, 0)}])
    with pytest.raises(ValueError, match=r"inner\[0\].*type"):
        as_primitives([{"type": "torus", "size": (0.05,), "pos": (0, 0, 0)}])
    with pytest.raises(ValueError, match="intersects the body"):
        box_scene("tight", gap=0.001)                              # closer than the cloth's own radius
    with pytest.raises(ValueError, match="start"):
        MujocoScene.from_primitives(BOX, "loose", start=(0.5, 0.0, 0.275), direction=(0, 0, -1), bounds=BOX_RANGE,
                                    base="cap", centre=(0.5, 0.0, 0.2), facing=(0, 0, 1), half_angle=80.0,
                                    spacing=0.03, slack=0.03)        # between the box and its cover
    with pytest.raises(ValueError, match="cover"):
        MujocoScene.from_primitives(BOX, "silk", start=(0.5, 0, 0.4), direction=(0, 0, -1), bounds=BOX_RANGE)


NAN = float("nan")


@pytest.mark.parametrize("option, value, message", [
    ("spacing", 0.0, "spacing: 0 m is below the supported minimum"),          # ZeroDivisionError
    ("spacing", -0.02, "spacing: -0.02 m is below"),
    ("spacing", 1e-5, "spacing: 1e-05 m is below"),                          # tried to allocate 2.3 GiB
    ("spacing", 0.001, "spacing: 0.001 m is below"),                         # mujoco.FatalError
    ("spacing", NAN, "spacing: must be finite"),                             # "cannot convert float NaN"
    ("timestep", 0.0, "timestep: 0 s is below"),                             # ZeroDivisionError
    ("settle_time", -1.0, "settle_time: -1 s is below"),
    ("settle_time", 1e5, "settle_time: 100000 s is above"),                  # hung
    ("camera_scale", 50.0, "camera_scale: 50 is above"),                     # tried to allocate 4 GiB
    ("sensor_noise", NAN, "sensor_noise: must be finite"),
    ("young", -5.0, "cover option young: -5 Pa is below"),                   # negative stiffness was accepted
    ("slack", NAN, "cover option slack: must be finite"),
])
def test_mujoco_options_are_bounded_before_anything_is_built(option, value, message):
    import time

    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=message):
        box_scene(**{option: value})
    assert time.perf_counter() - t0 < 5.0                  # refused up front, not after a settle


def test_too_many_or_tiny_primitives_and_names_that_are_not_xml():
    many = [{"type": "sphere", "size": (0.01,), "pos": (0.5, 0.0, 0.2)}] * 500
    with pytest.raises(ValueError, match="500 primitives; at most 64"):
        MujocoScene.from_primitives(many, "tight", start=(0.5, 0, 0.4), direction=(0, 0, -1), bounds=BOX_RANGE)
    with pytest.raises(ValueError, match=r"inner\[0\]: a box needs 3 size value\(s\) between 1 mm and 2 m"):
        as_primitives([{"type": "box", "size": (1e-5, 0.01, 0.01), "pos": (0.5, 0, 0.2)}])    # a MuJoCo XML error
    odd = box_scene("tight", name='box" <model> & "x')                      # was pasted into the XML unescaped
    assert odd.model.names.decode().split("\x00")[0] == 'box" <model> & "x'


def test_a_blow_up_is_reported_within_a_few_steps():
    """The check runs every ``CHECK_EVERY`` steps of a long ``step(n)``, not only at its end."""
    from torch_gpioius.sim.mujoco.hardware import MujocoPhysics

    scene = box_scene("tight")
    physics = MujocoPhysics(scene.model)
    physics.set_state(scene.settled)
    physics.data.qvel[-1] = float("nan")
    with pytest.raises(MujocoInstability, match="NaN"):
        physics.step(10_000)
    assert physics.time < scene.settle_time + 30 * scene.timestep


def test_a_blow_up_is_an_error_not_nan(scene):
    hw = scene.hardware()
    physics = hw.robot.physics
    physics.data.qvel[-1] = float("nan")          # MuJoCo would reset the state and only count a warning
    with pytest.raises(MujocoInstability, match="NaN"):
        physics.step(1)
    hw = scene.hardware()
    hw.robot.physics.data.qvel[hw.robot._dadr] = 3.0          # every arm joint at its speed limit: ~1 J
    hw.robot.physics.max_kinetic_energy = 0.1
    with pytest.raises(MujocoInstability, match="kinetic energy"):
        hw.robot.physics.step(1)


@pytest.mark.slow
def test_objects_e_to_h_build_and_settle():
    scenes = mujoco_objects_3d()
    for name, sc in scenes.items():
        assert union_sdf(sc.primitives, sc.cover_vertices()).min() > -2e-3, name
        assert sc.real_time_factor(0.2) > 0.1
    assert len(arm_primitives()) == 3


CAPSULE = [{"type": "capsule", "size": (0.05, 0.08), "pos": (0.5, 0.0, 0.2), "quat": (0.7071067811865476, 0.0,
                                                                                    0.7071067811865476, 0.0)}]


def capsule_scene(seed=0, **kw):
    """A 10 cm thick capsule lying along x under a loose cloth cap that settles 3 cm off it."""
    return MujocoScene.from_primitives(CAPSULE, "loose", start=(0.5, 0.01, 0.45), direction=(0, 0, -1),
                                       bounds=[[0.36, -0.12, 0.19], [0.64, 0.12, 0.32]], base="cap",
                                       centre=(0.5, 0, 0.2), facing=(0, 0, 1), half_angle=100.0, slack=0.03,
                                       name="capsule", **kw).perturbed(seed)


def test_under_loose_cloth_the_fingertip_touches_the_body_not_only_the_cloth():
    """The fingertip must reach the body through the cloth: with the cloth's default stiffness every contact of a
    short run on three seeds is on the capsule (at least 90 % is required). The earlier default (5e4 Pa at a 4 ms
    step) left 55-71 % on the body: the fingertip slid on a cloth that held it off the capsule."""
    for seed in range(3):
        trace = tg.explore(capsule_scene(seed), max_travel=0.15, metrics_every=100)
        on = trace.contacts_on_body()
        assert on["within"] >= 0.9 and on["on_body"] >= 0.9, (seed, on)


def test_a_mesh_body_collides_as_convex_parts_and_its_metrics_use_the_mesh(tmp_path, monkeypatch):
    import trimesh

    from torch_gpioius.sim.mujoco.bodies import MeshBody, convex_parts

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))           # a fresh decomposition cache
    profile = np.array([[0, 0], [30, 0], [30, 100], [26, 115], [12, 135], [12, 160], [0, 160]], dtype=float)
    bottle = trimesh.creation.revolve(profile, sections=32)
    bottle.apply_scale(0.001)
    bottle.apply_translation((0.5, 0.0, 0.1))
    scene = MujocoScene.from_mesh(bottle, "tight", start=(0.505, 0.004, 0.40), direction=(0, 0, -1),
                                  bounds=[[0.42, -0.08, 0.14], [0.58, 0.08, 0.3]], name="bottle", gap=0.008)
    assert isinstance(scene.body, MeshBody) and 1 <= len(scene.body) <= 32 and scene.primitives == []
    parts = convex_parts(bottle)                                   # cached: the same parts again
    assert len(parts) == len(scene.body.parts) and all(p.is_convex for p in parts)
    assert list((tmp_path / "torch_gpioius" / "coacd").glob("*.npz"))
    # the union of the parts follows the bottle: every part vertex within 4 mm of its surface
    assert max(np.abs(scene.body.sdf(p.vertices)).max() for p in parts) < 0.004
    # metrics use the mesh's exact distance: 1 cm from the wall's vertex line along +x, and between two vertex lines
    # (the middle of a flat facet) 4 cm - 3 cm cos(pi / 32)
    assert scene.true_distance(np.array([[0.54, 0.0, 0.15]]))[0] == pytest.approx(0.01, abs=1e-12)
    mid = 0.04 * np.array([math.cos(math.pi / 32), math.sin(math.pi / 32), 0.0]) + [0.5, 0.0, 0.15]
    assert scene.true_distance(mid[None])[0] == pytest.approx(0.04 - 0.03 * math.cos(math.pi / 32), abs=1e-12)
    trace = tg.explore(scene, max_travel=0.05, metrics_every=100)
    assert trace.terminated == "travel" and trace.contacts_on_body()["within"] == 1.0
    with pytest.raises(ValueError, match="collision"):
        MeshBody(bottle, "sdf")


def test_a_gel_pad_explores_under_the_simulated_cloth(scene, tmp_path):
    """touch="patch" in the MuJoCo world: the pad sees the body through the cloth where the cloth is pressed onto it
    (body + the 1 mm fabric) and the cloth alone where the cloth carries the force, and never free space inside the
    body. A loose cap over a box: most readings are pinched ones."""
    trace = tg.explore(scene, "visual-tactile", touch="patch", max_travel=0.04, metrics_every=100,
                       log=tmp_path / "run.gpioius")
    assert trace.n_steps >= 3 and not trace.terminated.startswith("refused")
    m = trace.model
    task, x, y = np.asarray(m.train_task), m.train_inputs[0].numpy(), m.train_targets.numpy()
    surf, free = x[(task == 0) & (y == 0)], x[(task == 0) & (y == 1)]
    assert len(surf) > 20 * trace.n_steps
    d = scene.true_distance(surf)
    pinched = np.abs(d - scene.cover.thickness) < 1e-6        # body + fabric, to the exact SDF's rounding
    assert pinched.mean() > 0.5, np.percentile(d, [10, 50, 90])
    assert (d > -1e-9).all()                                  # never inside the body
    assert (scene.true_distance(free) > 0).all()
    assert type(m._inference()).__name__ == "BatchedExactInference"


def test_more_views_see_more_of_the_scene_and_the_tripods_stay_where_they_stood(scene):
    """The MuJoCo world's views, as the force-field world's: each view's points lie on the cloth or the box (their
    ray-cast truth), three views see more than one and carry their own camera origins, a seed's perturbation moves
    the wrist view with the arm and leaves the tripods, and "default" settings bring the user's defaults."""
    from torch_gpioius.kernels import Matern52
    from torch_gpioius.sensors import MultiViewSource
    from torch_gpioius.sim.forcefield import VIEWS
    from torch_gpioius.sim.mujoco.hardware import MujocoPhysics

    three = scene.with_settings("default")
    assert three.views == VIEWS and scene.views == ("fixed",)
    assert isinstance(three.defaults.kernel, Matern52) and three.defaults.policy.touch_inside == 0.02
    assert three.defaults.approach_travel == scene.defaults.approach_travel           # the MuJoCo world's own
    one, many = scene.hardware().camera.capture(), three.hardware().camera.capture()
    assert len(many.points) > 1.5 * len(one.points)
    origins = np.unique(np.round(np.asarray(many.origin), 6), axis=0)
    assert len(origins) == 3
    # every point is on a surface the rays can hit: the settled cloth's elements or the box (within the noise)
    physics = MujocoPhysics(three.model)
    physics.set_state(three.settled)
    cloth = np.asarray(physics.data.flexvert_xpos, dtype=np.float64)
    pts = np.asarray(many.points)
    to_cloth = np.min(np.linalg.norm(pts[:, None, :] - cloth[None, ::1, :], axis=-1), axis=1)
    to_box = np.abs(three.true_distance(pts))
    near = (to_cloth < 0.03) | (to_box < 0.01) | (pts[:, 2] < BOX_RANGE[0][2] - 0.05)     # or the table below
    assert near.mean() > 0.99
    # the tripods stand where the unperturbed approach put them; the wrist follows the arm
    moved = three.perturbed(3)
    assert not np.allclose(moved.direction, three.direction)
    a, b = three.cameras(physics, VIEWS), moved.cameras(physics, VIEWS)
    assert isinstance(a, MultiViewSource)
    np.testing.assert_allclose(a.sources[0].T_base_camera, b.sources[0].T_base_camera)
    np.testing.assert_allclose(a.sources[1].T_base_camera, b.sources[1].T_base_camera)
    assert not np.allclose(a.sources[2].T_base_camera, b.sources[2].T_base_camera)
    assert scene.with_settings("paper").views == ("fixed",)
    with pytest.raises(ValueError, match="settings"):
        scene.with_settings("mine")
    # other views keep the settings: the defaults seen by the fixed camera alone, the paper's by all three
    alone = three.with_views(1)
    assert alone.views == ("fixed",) and alone.defaults is three.defaults
    np.testing.assert_allclose(alone.cameras(physics, ("fixed",)).T_base_camera, a.sources[0].T_base_camera)
    assert scene.with_views(3).views == VIEWS and scene.with_views(3).defaults is scene.defaults
    with pytest.raises(ValueError, match="views"):
        scene.with_views("side")
    # other estimator settings keep the views and the cover: changes on the scene's own (a scene file's [estimator])
    from torch_gpioius.models.overrides import EstimatorOverrides

    changed = three.with_estimator(EstimatorOverrides(noise=0.05, labels={"ray_smoothing": None}))
    assert changed.views == three.views and changed.defaults.estimator == three.defaults.estimator.replace(
        noise=0.05, labels={"ray_smoothing": None})
    assert three.with_estimator({"learn": "length"}).defaults.learn == "length"
    with pytest.raises(ValueError, match="estimator"):
        three.with_estimator("paper")


def test_a_camera_error_moves_the_mujoco_cameras_captures_by_each_views_draw(scene):
    """Issue 63, item 1, in the MuJoCo world: the capture of a camera off by 6 mm and a degree is the calibrated one
    (the same noise) moved by the draw the scene reports, about the camera's reported origin; the error survives a
    seed's perturbation and changes the scene's fingerprint."""
    from torch_gpioius.sensors.simulated.camera import AppliedCameraError

    off = scene.with_camera_error("6mm,1deg")
    assert scene.camera_errors() == {} and set(off.camera_errors()) == {"fixed"}
    e = off.camera_errors()["fixed"]
    assert e["size_mm"] == pytest.approx(6.0) and e["angle_deg"] == pytest.approx(1.0)
    a, b = scene.hardware().camera.capture(), off.hardware().camera.capture()
    applied = AppliedCameraError(tuple(np.asarray(e["translation_mm"]) / 1e3), tuple(np.radians(e["rotation_deg"])))
    np.testing.assert_allclose(b.points, applied.apply(a.points, a.origin), atol=1e-6)   # the record's rounding
    np.testing.assert_array_equal(a.origin, b.origin)
    assert off.fingerprint() != scene.fingerprint() and off.perturbed(2).camera_error == off.camera_error
