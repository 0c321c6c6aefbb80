"""UR5 kinematics against an independent DH product, finite differences and round trips."""

import math

import numpy as np
import pytest
import torch

from kinematics import UR5, UnreachablePoseError, ur5_urdf
from kinematics.ur5 import _so3_log

# The published UR5 (CB3) table, typed here independently of kinematics/dh.py.
D = [0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823]
A = [0.0, -0.425, -0.39225, 0.0, 0.0, 0.0]
ALPHA = [math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0]


def dh_forward(q, tool=(0.0, 0.0, 0.0)):
    """Standard DH product Rz(q) Tz(d) Tx(a) Rx(alpha), in NumPy."""
    T = np.eye(4)
    for qi, d, a, al in zip(q, D, A, ALPHA):
        ct, st, ca, sa = math.cos(qi), math.sin(qi), math.cos(al), math.sin(al)
        T = T @ np.array([[ct, -st * ca, st * sa, a * ct],
                          [st, ct * ca, -ct * sa, a * st],
                          [0.0, sa, ca, d],
                          [0.0, 0.0, 0.0, 1.0]])
    Tt = np.eye(4)
    Tt[:3, 3] = tool
    return T @ Tt


@pytest.fixture(scope="module")
def ur5():
    return UR5(tool_offset=(0.01, -0.02, 0.05))


def random_q(n, seed=0, span=math.pi):
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(n, 6, generator=g, dtype=torch.float64) * 2 - 1) * span


def test_bundled_urdf_is_the_generated_one():
    from importlib import resources
    assert resources.files("kinematics").joinpath("ur5.urdf").read_text() == ur5_urdf()


def test_forward_kinematics_matches_dh_product(ur5):
    q = random_q(200, seed=1, span=2 * math.pi)
    T = ur5.forward_kinematics(q)
    assert T.shape == (200, 4, 4) and T.dtype == torch.float64
    ref = np.stack([dh_forward(qi.tolist(), (0.01, -0.02, 0.05)) for qi in q])
    assert np.abs(T.numpy() - ref).max() < 1e-12
    flange = ur5.forward_kinematics(q[:5], frame="flange")
    assert np.abs(flange.numpy() - np.stack([dh_forward(qi.tolist()) for qi in q[:5]])).max() < 1e-12


def test_zero_configuration_is_the_published_home(ur5):
    # With all joints at 0 the UR5 is stretched along -x of the base: x = a2 + a3, y = -(d4 + d6), z = d1 - d5.
    p = UR5().position(torch.zeros(6, dtype=torch.float64))
    assert torch.allclose(p, torch.tensor([-0.81725, -0.19145, -0.005491], dtype=torch.float64), atol=1e-12)


def test_jacobian_matches_finite_differences(ur5):
    h = 1e-6
    for q in random_q(5, seed=2):
        J = ur5.jacobian(q)
        T0 = ur5.forward_kinematics(q)
        for j in range(6):
            e = torch.zeros(6, dtype=torch.float64)
            e[j] = h
            Tp, Tm = ur5.forward_kinematics(q + e), ur5.forward_kinematics(q - e)
            dp = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
            dR = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ T0[:3, :3].T   # skew(omega)
            w = torch.stack([dR[2, 1], dR[0, 2], dR[1, 0]])
            assert torch.allclose(J[:3, j], dp, atol=1e-8)
            assert torch.allclose(J[3:, j], w, atol=1e-8)


def test_inverse_kinematics_round_trip(ur5):
    q_true = random_q(12, seed=3, span=math.pi)
    T = ur5.forward_kinematics(q_true)
    q = ur5.inverse_kinematics(T)
    T2 = ur5.forward_kinematics(q)
    pos = (T2[:, :3, 3] - T[:, :3, 3]).norm(dim=-1)
    rot = _so3_log(T2[:, :3, :3] @ T[:, :3, :3].transpose(-1, -2)).norm(dim=-1)
    assert float(pos.max()) < 1e-4 and float(rot.max()) < 1e-3
    assert bool(ur5.within_limits(q).all())


def test_inverse_kinematics_prefers_the_configuration_near_q_init(ur5):
    q_true = torch.tensor([0.3, -1.1, 1.4, -1.8, -1.6, 0.2], dtype=torch.float64)
    q = ur5.inverse_kinematics(ur5.forward_kinematics(q_true), q_init=q_true + 0.05)
    assert float((q - q_true).abs().max()) < 1e-6


def test_inverse_kinematics_unreachable_raises(ur5):
    T = torch.eye(4, dtype=torch.float64)
    T[:3, 3] = torch.tensor([2.0, 0.0, 0.5])
    with pytest.raises(UnreachablePoseError, match="no joint configuration"):
        ur5.inverse_kinematics(T, num_retries=4)
    bad = T.clone()
    bad[0, 0] = 2.0
    with pytest.raises(ValueError, match="rotation"):
        ur5.inverse_kinematics(bad)


def regular_configs():
    return [torch.tensor(q, dtype=torch.float64) for q in
            ([0.0, -1.2, 1.5, -1.9, -1.57, 0.0], [0.7, -1.6, 1.1, -1.0, -1.2, 0.4], [-0.5, -0.9, 2.0, -2.4, 1.3, 1.0])]


@pytest.mark.parametrize("hold", [True, False])
def test_cartesian_step_realises_dx(ur5, hold):
    g = torch.Generator().manual_seed(4)
    for q in regular_configs():
        dx = (torch.rand(3, generator=g, dtype=torch.float64) - 0.5) * 0.02
        q2 = ur5.cartesian_step(q, dx, hold_orientation=hold)
        assert torch.allclose(ur5.position(q2) - ur5.position(q), dx, atol=1e-9)
        if hold:
            R0, R1 = ur5.forward_kinematics(q)[:3, :3], ur5.forward_kinematics(q2)[:3, :3]
            assert float(_so3_log(R1 @ R0.T).norm()) < 1e-9


def test_cartesian_step_batched_equals_single(ur5):
    qs = torch.stack(regular_configs())
    dx = torch.tensor([[0.01, 0.0, 0.0], [0.0, -0.01, 0.0], [0.0, 0.0, 0.005]], dtype=torch.float64)
    batched = ur5.cartesian_step(qs, dx)
    for i in range(3):
        assert torch.allclose(batched[i], ur5.cartesian_step(qs[i], dx[i]), atol=1e-12)


def test_cartesian_step_gradients_match_finite_differences(ur5):
    q = regular_configs()[1]
    dx = torch.tensor([0.004, -0.003, 0.002], dtype=torch.float64)
    Jdx = torch.autograd.functional.jacobian(lambda d: ur5.cartesian_step(q, d), dx)
    Jq = torch.autograd.functional.jacobian(lambda qq: ur5.cartesian_step(qq, dx), q)
    h = 1e-6
    fd_dx = torch.stack([(ur5.cartesian_step(q, dx + h * e) - ur5.cartesian_step(q, dx - h * e)) / (2 * h)
                         for e in torch.eye(3, dtype=torch.float64)], dim=1)
    fd_q = torch.stack([(ur5.cartesian_step(q + h * e, dx) - ur5.cartesian_step(q - h * e, dx)) / (2 * h)
                        for e in torch.eye(6, dtype=torch.float64)], dim=1)
    assert torch.isfinite(Jdx).all() and torch.isfinite(Jq).all()
    assert torch.allclose(Jdx, fd_dx, atol=1e-6, rtol=1e-6)
    assert torch.allclose(Jq, fd_q, atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize("q", [
    [0.0, -1.2, 1.5, -1.9, 0.0, 0.0],      # wrist singularity: q5 = 0, axes 4 and 6 aligned
    [0.0, -1.2, 0.0, -1.9, -1.5, 0.0],     # elbow singularity: arm stretched, q3 = 0
    [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],        # stretched along -x (elbow and wrist together)
])
def test_cartesian_step_near_singularities_stays_bounded(ur5, q):
    q = torch.tensor(q, dtype=torch.float64)
    for direction in torch.eye(3, dtype=torch.float64):
        for sign in (1.0, -1.0):
            dx = sign * 0.01 * direction
            q2 = ur5.cartesian_step(q, dx)
            assert torch.isfinite(q2).all()
            assert float((q2 - q).abs().max()) <= ur5.max_joint_step + 1e-12
            # never moves the fingertip further than asked (damped, not amplified)
            assert float((ur5.position(q2) - ur5.position(q)).norm()) <= 0.0101
            g = torch.autograd.functional.jacobian(lambda d: ur5.cartesian_step(q, d), dx)
            assert torch.isfinite(g).all()


def test_cartesian_step_respects_joint_limits():
    ur5 = UR5()
    q = torch.tensor([0.0, -1.2, 1.5, -1.9, -1.57, 0.0], dtype=torch.float64)
    q[0] = ur5.upper[0] - 2e-3
    # a step whose plain solution rotates the base (joint 0) past its limit
    J = ur5.jacobian(q)
    v = torch.linalg.pinv(J)[0, :3]       # the Cartesian direction that drives joint 0 most
    q2 = ur5.cartesian_step(q, 0.02 * v / v.norm())
    assert bool(ur5.within_limits(q2))
    assert float(q2[0]) <= float(ur5.upper[0]) - ur5.limit_margin + 1e-12


def test_bad_inputs_are_rejected(ur5):
    q = regular_configs()[0]
    with pytest.raises(ValueError, match="NaN"):
        ur5.forward_kinematics(torch.full((6,), float("nan"), dtype=torch.float64))
    with pytest.raises(ValueError, match=r"\(\.\.\., 6\)"):
        ur5.forward_kinematics(torch.zeros(5, dtype=torch.float64))
    with pytest.raises(ValueError, match="dx"):
        ur5.cartesian_step(q, torch.tensor([0.0, float("inf"), 0.0]))
    with pytest.raises(ValueError, match="tool_offset"):
        UR5(tool_offset=(0.0, 0.1))


def test_the_pose_cache_gives_the_computed_pose_to_the_bit_and_keeps_autograd():
    """The last few joint vectors' poses are kept (a guarded move asked ~11 poses a move, half of them repeats): a
    cached pose is the computed one bit for bit, a later change of the returned tensor does not reach the cache, and
    joints that require a gradient are always computed, so the pose stays differentiable."""
    import torch

    from kinematics.ur5 import UR5

    ur5 = UR5(tool_offset=(0.0, 0.0, 0.05))
    q = torch.tensor([0.1, -1.2, 1.4, -1.7, -1.5, 0.2], dtype=torch.float64)
    fresh = UR5(tool_offset=(0.0, 0.0, 0.05)).forward_kinematics(q)
    first = ur5.forward_kinematics(q)
    first[0, 0] = 123.0                                   # the caller's copy, not the cache
    again = ur5.forward_kinematics(q.clone())
    assert torch.equal(again, fresh) and torch.equal(ur5.forward_kinematics(q, frame="flange"),
                                                     UR5(tool_offset=(0.0, 0.0, 0.05)).forward_kinematics(
                                                         q, frame="flange"))
    qg = q.clone().requires_grad_(True)
    ur5.position(qg).sum().backward()
    assert qg.grad is not None and bool(torch.isfinite(qg.grad).all()) and float(qg.grad.abs().sum()) > 0
    for k in range(20):                                   # bounded: the oldest are dropped
        ur5.forward_kinematics(q + 0.01 * k)
    assert len(ur5._fk_cache) <= 8


def test_closed_form_frames_equal_the_pytorch_kinematics_chain(ur5):
    """The DH fast path (kinematics.dh.dh_forward / dh_jacobian) against the chain pytorch-kinematics builds from
    the bundled URDF: poses and Jacobians of the fingertip (tool offset off the flange axis), batched."""
    q = random_q(64, seed=11, span=2 * math.pi)
    T_chain = ur5.chain.forward_kinematics(q).get_matrix() @ ur5.T_flange_tool
    J_chain = ur5.chain.jacobian(q, locations=ur5.tool_offset)
    assert torch.allclose(ur5.forward_kinematics(q), T_chain, rtol=0, atol=1e-12)
    assert torch.allclose(ur5.jacobian(q), J_chain, rtol=0, atol=1e-12)
    flange = ur5.chain.forward_kinematics(q).get_matrix()
    assert torch.allclose(ur5.forward_kinematics(q, frame="flange"), flange, rtol=0, atol=1e-12)


@pytest.mark.parametrize("length", [1e-3, 2e-3, 1e-2])
def test_cartesian_step_stops_iterating_once_converged(length):
    """A millimetre step converges in two Newton iterations; more allowed iterations change nothing, and the
    realised step still matches dx far below a micrometre."""
    q = regular_configs()[1]
    dx = torch.tensor([0.6, -0.48, 0.64], dtype=torch.float64) * length
    steps = {}
    for iterations in (3, 6):
        arm = UR5(tool_offset=(0.01, -0.02, 0.05), newton_iterations=iterations)
        steps[iterations] = arm.cartesian_step(q, dx)
        assert torch.allclose(arm.position(steps[iterations]) - arm.position(q), dx, rtol=0, atol=1e-10)
    assert torch.equal(steps[3], steps[6])


def test_repeated_steps_start_from_the_last_joint_step_and_land_where_a_cold_start_does():
    """An approach's repeated 1 mm step is warm-started from the previous joint step (outside autograd): every
    step lands where a fresh arm's cold start lands (both stop within NEWTON_TOLERANCE of the goal: 1e-9 rad apart)
    and moves the fingertip by dx; a warm start from far away (the same dx asked at other joints) is started cold."""
    warm = UR5(tool_offset=(0.01, -0.02, 0.05))
    dx = torch.tensor([0.0006, -0.0003, -0.0007], dtype=torch.float64)
    q = regular_configs()[0]
    with torch.no_grad():
        for _ in range(20):
            cold = UR5(tool_offset=(0.01, -0.02, 0.05)).cartesian_step(q, dx)
            q_next = warm.cartesian_step(q, dx)
            assert torch.allclose(q_next, cold, rtol=0, atol=1e-9)
            assert torch.allclose(warm.position(q_next) - warm.position(q), dx, rtol=0, atol=1e-10)
            q = q_next
        elsewhere = regular_configs()[2]
        q_far = warm.cartesian_step(elsewhere, dx)
        assert torch.allclose(warm.position(q_far) - warm.position(elsewhere), dx, rtol=0, atol=1e-10)
        assert float((q_far - elsewhere).abs().max()) < 0.05


def test_one_joint_vector_in_numpy_equals_the_batched_torch_path(ur5):
    """kinematics.single (one joint vector, no gradient) against the torch functions of a batch: poses, Jacobians,
    pose errors and damped steps, the last near a singularity and with joints locked at their limits."""
    from kinematics import single
    from kinematics.dh import UR5_DH, dh_forward, dh_jacobian
    from kinematics.ik import dls_step
    from kinematics.ur5 import pose_error

    qs = random_q(16, seed=5, span=2 * math.pi)
    batch = ur5.forward_kinematics(qs)
    frames = dh_forward(qs, UR5_DH)
    J_batch = dh_jacobian(frames, frames[:, -1, :3, 3])
    for i, q in enumerate(qs):
        assert torch.allclose(ur5.forward_kinematics(q), batch[i], rtol=0, atol=1e-12)
        fr = single.frames(q.numpy(), UR5_DH)
        np.testing.assert_allclose(fr, frames[i].numpy(), rtol=0, atol=1e-12)
        np.testing.assert_allclose(single.jacobian(fr, fr[-1, :3, 3]), J_batch[i].numpy(), rtol=0, atol=1e-12)
        other = batch[(i + 1) % len(qs)]
        ref = pose_error(other[None], batch[i][None])[0]
        if float(torch.trace(other[:3, :3] @ batch[i][:3, :3].T)) > 1.0:      # under 90 degrees apart
            np.testing.assert_allclose(single.pose_error(other.numpy(), batch[i].numpy()), ref.numpy(), atol=1e-12)
        else:
            assert single.pose_error(other.numpy(), batch[i].numpy()) is None
    g = torch.Generator().manual_seed(2)
    lower, upper = ur5.lower, ur5.upper
    for k in range(12):
        J = torch.randn(6, 6, generator=g, dtype=torch.float64)
        if k % 3 == 1:
            J[:, 5] = J[:, 4] * (1 + 1e-4)                   # near-singular: damped
        v = torch.randn(6, generator=g, dtype=torch.float64) * 0.01
        q = torch.zeros(6, dtype=torch.float64)
        if k % 3 == 2:
            q[1] = float(upper[1]) - 2e-3                      # a joint at its limit: locked when it moves out
        kw = dict(max_damping=0.05, threshold=0.05, limit_margin=1e-3)
        ref = dls_step(J[None], v[None], q[None], lower, upper, max_joint_step=math.inf, **kw)[0]
        got = single.dls_step(J.numpy(), v.numpy(), q.numpy(), lower.numpy(), upper.numpy(), **kw)
        np.testing.assert_allclose(got, ref.numpy(), rtol=0, atol=1e-12)
