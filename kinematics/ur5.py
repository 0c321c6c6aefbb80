"""The UR5 (CB3) model: forward kinematics, inverse kinematics and the differentiable Cartesian step.

Frames: ``base`` is the UR controller's base frame (DH frame 0); ``flange`` is DH frame 6; ``tool`` is the
fingertip, ``T_flange_tool`` a pure translation ``tool_offset`` in the flange frame. All transforms are
homogeneous `(4, 4)` matrices named ``T_<to>_<from>``, float64, metres and radians.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from importlib import resources
from typing import Sequence

import numpy as np
import pytorch_kinematics as pk
import torch

from . import single
from .dh import UR5_DH, UR5_JOINT_LIMITS, UR5_VELOCITY_LIMITS, dh_forward, dh_jacobian
from .ik import dls_step

__all__ = ["UR5", "UnreachablePoseError", "pose_error", "load_chain", "tool_rotation", "NEWTON_TOLERANCE"]

#: A Cartesian step's Newton iterations stop once the pose error is below this [m, rad]: far below any joint
#: encoder's resolution (~1e-5 rad), and reached after two iterations by a millimetre step.
NEWTON_TOLERANCE = 1e-10


def tool_rotation(direction) -> torch.Tensor:
    """`(3, 3)` ``R_base_tool`` whose z axis (the fingertip's pointing direction) is ``direction`` `(3,)`.

    The tool's x axis is the base x axis made orthogonal to z (the base y axis when z is nearly along x).
    """
    z = torch.as_tensor(direction, dtype=torch.float64)
    if z.shape != (3,) or not bool(torch.isfinite(z).all()) or float(z.norm()) == 0:
        raise ValueError(f"direction: expected a finite non-zero (3,) vector, got {direction!r}")
    z = z / z.norm()
    helper = torch.tensor([1.0, 0.0, 0.0] if abs(float(z[0])) < 0.9 else [0.0, 1.0, 0.0], dtype=torch.float64)
    x = torch.linalg.cross(helper, z)
    x = x / x.norm()
    return torch.stack([x, torch.linalg.cross(z, x), z], dim=1)


def _convert_transform_float64(origin):  # noqa: ANN001 - urdf_parser_py's Pose
    """pytorch-kinematics' URDF origin conversion, in float64."""
    if origin is None:
        return pk.Transform3d(dtype=torch.float64)
    rpy = torch.tensor(origin.rpy, dtype=torch.float64)
    return pk.Transform3d(rot=pk.quaternion_from_euler(rpy, "sxyz"),
                          pos=torch.tensor(origin.xyz, dtype=torch.float64), dtype=torch.float64)


def load_chain(urdf: bytes, end_link: str, device: torch.device | str = "cpu") -> pk.SerialChain:
    """``pk.build_serial_chain_from_urdf`` with every joint and link origin exact in float64.

    pytorch-kinematics 0.10 converts URDF ``rpy`` through a float32 tensor, so a DH twist of pi/2 leaves
    cos(pi/2) ~ -4e-8 in the chain and FK errs by ~2e-8 m; ``.to(float64)`` afterwards cannot recover it.
    So the chain pytorch-kinematics builds is kept for its frame tree, each frame's origin is re-converted
    from the URDF in float64, and the serial chain is then built in float64 from that tree.
    """
    robot = pk.URDF.from_xml_string(urdf)
    tree = pk.build_chain_from_urdf(urdf)
    stack = [tree._root]
    while stack:
        fr = stack.pop()
        stack.extend(fr.children)
        if fr.joint.name in robot.joint_map:
            fr.joint.offset = _convert_transform_float64(robot.joint_map[fr.joint.name].origin)
        if fr.link.name in robot.link_map:
            fr.link.offset = _convert_transform_float64(getattr(robot.link_map[fr.link.name], "origin", None))
    return pk.SerialChain(tree, end_link, dtype=torch.float64, device=device)


class UnreachablePoseError(ValueError):
    """Raised when inverse kinematics finds no configuration within tolerance and the joint limits."""


# the entries (2, 1), (0, 2), (1, 0) of a matrix: vee(R - R^T) = R[rows, cols] - R[cols, rows]
_VEE_ROWS, _VEE_COLS = [2, 0, 1], [1, 2, 0]


def _so3_log(R: torch.Tensor) -> torch.Tensor:
    """Rotation vector (axis · angle) of `(..., 3, 3)` rotation matrices, with finite gradients at identity.

    pytorch-kinematics' ``matrix_to_axis_angle`` goes through ``acos`` and has an infinite derivative at the
    identity, exactly where a pose-tracking Newton step lives; so small rotations (angle < 90 deg) use
    ``theta / sin(theta) · vee(R - R^T) / 2`` with ``theta = atan2(|s|, c)`` and its series near 0, large
    ones pytorch-kinematics' robust formula.
    """
    # (few operations: a guarded motion takes this log several times a millimetre)
    s = 0.5 * (R[..., _VEE_ROWS, _VEE_COLS] - R[..., _VEE_COLS, _VEE_ROWS])
    c = 0.5 * (torch.diagonal(R, dim1=-2, dim2=-1).sum(-1) - 1.0)
    s2 = (s * s).sum(-1)
    small = s2 < 1e-12
    sn = torch.sqrt(torch.where(small, 1.0, s2))
    factor = torch.where(small, 1.0 + s2 / 6.0, torch.atan2(sn, c) / sn)
    near = s * factor[..., None]
    if bool((c > 0).all()):
        return near
    far = pk.matrix_to_axis_angle(R)
    return torch.where((c > 0)[..., None], near, far)


def pose_error(T_target: torch.Tensor, T: torch.Tensor) -> torch.Tensor:
    """Twist-like error ``[p_target - p, log(R_target R^T)]`` in the base frame.

    Args:
        T_target: `(..., 4, 4)` target poses.
        T: `(..., 4, 4)` current poses.

    Returns:
        `(..., 6)`: position error [m] and rotation-vector error [rad], both in the base frame (so that
        ``J dq = error`` is the Newton step with the base-frame geometric Jacobian).
    """
    dp = T_target[..., :3, 3] - T[..., :3, 3]
    dR = T_target[..., :3, :3] @ T[..., :3, :3].transpose(-1, -2)
    return torch.cat([dp, _so3_log(dR)], dim=-1)


class UR5:
    """UR5 (CB3) kinematics on the bundled URDF, loaded with pytorch-kinematics.

    Args:
        tool_offset: `(3,)` fingertip position in the flange frame [m].
        device: torch device for the chain and all results.
        max_damping: DLS damping at an exact singularity (see :func:`kinematics.ik.adaptive_damping`).
        singular_threshold: smallest Jacobian singular value below which damping starts.
        max_joint_step: largest joint change :meth:`cartesian_step` returns [rad].
        limit_margin: distance :meth:`cartesian_step` keeps from joint limits [rad].
        newton_iterations: DLS iterations per Cartesian step (1 = the classic first-order resolved-rate step).

    Example:
        >>> ur5 = UR5(tool_offset=(0.0, 0.0, 0.05))
        >>> q = torch.tensor([0.0, -1.2, 1.5, -1.9, -1.57, 0.0], dtype=torch.float64)
        >>> T = ur5.forward_kinematics(q)          # (4, 4) T_base_tool
        >>> q2 = ur5.cartesian_step(q, torch.tensor([0.01, 0.0, 0.0], dtype=torch.float64))
    """

    dof = 6

    def __init__(
        self,
        tool_offset: Sequence[float] | torch.Tensor = (0.0, 0.0, 0.0),
        *,
        device: torch.device | str = "cpu",
        max_damping: float = 0.05,
        singular_threshold: float = 0.05,
        max_joint_step: float = 0.1,
        limit_margin: float = 1e-3,
        newton_iterations: int = 3,
    ) -> None:
        self.dtype = torch.float64
        self.device = torch.device(device)
        offset = torch.as_tensor(tool_offset, dtype=self.dtype, device=self.device)
        if offset.shape != (3,) or not bool(torch.isfinite(offset).all()):
            raise ValueError(f"tool_offset must be 3 finite numbers [m], got {tuple(offset.shape)} {offset}")
        self.tool_offset = offset
        self.urdf = resources.files("kinematics").joinpath("ur5.urdf").read_bytes()
        self.chain = load_chain(self.urdf, "flange", self.device)
        self.lower = torch.tensor([lo for lo, _ in UR5_JOINT_LIMITS], dtype=self.dtype, device=self.device)
        self.upper = torch.tensor([hi for _, hi in UR5_JOINT_LIMITS], dtype=self.dtype, device=self.device)
        self.max_velocity = torch.tensor(UR5_VELOCITY_LIMITS, dtype=self.dtype, device=self.device)
        self.max_damping = float(max_damping)
        self.singular_threshold = float(singular_threshold)
        self.max_joint_step = float(max_joint_step)
        self.limit_margin = float(limit_margin)
        self.newton_iterations = int(newton_iterations)
        # the poses of the last few single joint vectors: a guarded move reads the pose of the joints it stands at
        # several times (the step's start, the realised displacement, the force sensor, the next step's start)
        self._fk_cache: OrderedDict = OrderedDict()
        # the last single Cartesian step outside autograd: (its key, its joint step), a warm start for the next
        self._last_step: tuple = (None, None)
        T = torch.eye(4, dtype=self.dtype, device=self.device)
        T[:3, 3] = offset
        self.T_flange_tool = T
        self._T_flange_tool_np = T.cpu().numpy()
        self._limits_np = (self.lower.cpu().numpy(), self.upper.cpu().numpy())

    # ------------------------------------------------------------------------------------------ helpers
    def _q(self, q: torch.Tensor | Sequence[float]) -> torch.Tensor:
        q = torch.as_tensor(q, dtype=self.dtype, device=self.device)
        if q.shape[-1:] != (6,):
            raise ValueError(f"joint positions must have shape (..., 6), got {tuple(q.shape)}")
        if not bool(torch.isfinite(q).all()):
            raise ValueError("joint positions contain NaN or inf")
        return q

    def within_limits(self, q: torch.Tensor) -> torch.Tensor:
        """`(...)` bool: every joint of ``q`` `(..., 6)` inside its position limits."""
        q = self._q(q)
        return ((q >= self.lower) & (q <= self.upper)).all(dim=-1)

    # ------------------------------------------------------------------------------------------ kinematics
    def forward_kinematics(self, q: torch.Tensor | Sequence[float], *, frame: str = "tool") -> torch.Tensor:
        """Pose of the fingertip (or flange) in the base frame.

        Args:
            q: `(..., 6)` joint positions [rad].
            frame: ``"tool"`` (fingertip, ``tool_offset`` applied) or ``"flange"`` (DH frame 6).

        Returns:
            `(..., 4, 4)` ``T_base_tool`` (or ``T_base_flange``); differentiable w.r.t. ``q``.
        """
        q = self._q(q)
        if frame not in ("tool", "flange"):
            raise ValueError(f"frame must be 'tool' or 'flange', got {frame!r}")
        batch = q.shape[:-1]
        # one joint vector outside autograd: the same joints give the same pose to the bit, so the last few are kept
        # (why by hand: pytorch_kinematics has no cache; a slide's small moves asked ~11 poses each, half repeats)
        key = None
        if q.numel() == 6 and not (q.requires_grad and torch.is_grad_enabled()):
            key = self._pose_key(q, frame)
            hit = self._fk_cache.get(key)
            if hit is not None:
                self._fk_cache.move_to_end(key)
                return hit.clone().reshape(*batch, 4, 4)
        if key is not None:                        # one joint vector, no gradient: NumPy (kinematics.single)
            T_np = single.frames(q.detach().cpu().numpy().reshape(6).astype(np.float64), UR5_DH)[-1]
            if frame == "tool":
                T_np = T_np @ self._T_flange_tool_np
            T = torch.as_tensor(T_np, dtype=self.dtype, device=self.device)
            self._keep_pose(key, T)
            return T.clone().reshape(*batch, 4, 4)
        T = dh_forward(q.reshape(-1, 6), UR5_DH)[:, -1]
        if frame == "tool":
            T = T @ self.T_flange_tool
        return T.reshape(*batch, 4, 4)

    def _pose_key(self, q: torch.Tensor, frame: str) -> tuple:
        return (frame, id(self.T_flange_tool), q.device, q.dtype, q.detach().cpu().numpy().tobytes())

    def _keep_pose(self, key: tuple, T: torch.Tensor) -> None:
        self._fk_cache[key] = T.detach().clone().reshape(4, 4)
        if len(self._fk_cache) > 8:
            self._fk_cache.popitem(last=False)

    def position(self, q: torch.Tensor | Sequence[float]) -> torch.Tensor:
        """`(..., 3)` fingertip position in the base frame [m] for `(..., 6)` joints ``q``."""
        return self.forward_kinematics(q)[..., :3, 3]

    def jacobian(self, q: torch.Tensor | Sequence[float]) -> torch.Tensor:
        """Geometric Jacobian of the fingertip in the base frame.

        Args:
            q: `(..., 6)` joint positions [rad].

        Returns:
            `(..., 6, 6)`: rows 0-2 linear velocity [m/rad], rows 3-5 angular velocity [rad/rad], both in
            the base frame; differentiable w.r.t. ``q``.
        """
        q = self._q(q)
        batch = q.shape[:-1]
        frames, T = self._frames_and_tool(q.reshape(-1, 6))
        return dh_jacobian(frames, T[:, :3, 3]).reshape(*batch, 6, 6)

    def _frames_and_tool(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The DH frames `(B, 6, 4, 4)` (:func:`kinematics.dh.dh_forward`) and the fingertip poses `(B, 4, 4)` at
        `(B, 6)` joints: what a Jacobian and a pose error are both made from."""
        frames = dh_forward(q, UR5_DH)
        return frames, frames[:, -1] @ self.T_flange_tool

    def inverse_kinematics(
        self,
        T_base_tool: torch.Tensor,
        q_init: torch.Tensor | Sequence[float] | None = None,
        *,
        pos_tol: float = 1e-5,
        rot_tol: float = 1e-5,
        num_retries: int = 32,
        seed: int = 0,
    ) -> torch.Tensor:
        """Joint positions that put the fingertip at ``T_base_tool``.

        pytorch-kinematics' ``PseudoInverseIK`` searches from ``q_init`` and ``num_retries`` seeded random
        configurations within the joint limits; the converged solution closest to ``q_init`` (or with the
        smallest error) is then polished by undamped Newton steps in float64 to ``pos_tol`` / ``rot_tol``.

        Args:
            T_base_tool: `(..., 4, 4)` target fingertip poses in the base frame.
            q_init: `(6,)` or `(..., 6)` preferred configuration (e.g. the current one), or None.
            pos_tol: position tolerance [m].
            rot_tol: orientation tolerance [rad].
            num_retries: random restarts per target.
            seed: seed of the restarts (results are deterministic).

        Returns:
            `(..., 6)` joint positions [rad] within the joint limits.

        Raises:
            UnreachablePoseError: a target has no solution within tolerance (names which one and the error).
        """
        T_target = torch.as_tensor(T_base_tool, dtype=self.dtype, device=self.device)
        if T_target.shape[-2:] != (4, 4):
            raise ValueError(f"T_base_tool must have shape (..., 4, 4), got {tuple(T_target.shape)}")
        if not bool(torch.isfinite(T_target).all()):
            raise ValueError("T_base_tool contains NaN or inf")
        batch = T_target.shape[:-2]
        T_target = T_target.reshape(-1, 4, 4)
        R = T_target[:, :3, :3]
        ortho = (R @ R.transpose(-1, -2) - torch.eye(3, dtype=self.dtype, device=self.device)).abs().amax()
        if float(ortho) > 1e-6 or bool((torch.linalg.det(R) < 0).any()):
            raise ValueError("T_base_tool's rotation part is not a proper rotation matrix")
        T_flange = T_target @ torch.linalg.inv(self.T_flange_tool)
        gen = torch.Generator(device="cpu").manual_seed(seed)
        seeds = self.lower.cpu() + (self.upper - self.lower).cpu() * torch.rand(num_retries, 6, generator=gen,
                                                                               dtype=self.dtype)
        seeds = seeds.to(self.device)
        if q_init is not None:
            q0 = self._q(q_init).reshape(-1, 6)
            if q0.shape[0] != 1:
                raise ValueError("q_init must be one configuration (6,)")
            seeds = torch.cat([q0, seeds[:-1]], dim=0)
        solver = pk.PseudoInverseIK(
            self.chain, pos_tolerance=pos_tol * 10, rot_tolerance=rot_tol * 10, retry_configs=seeds,
            joint_limits=torch.stack([self.lower, self.upper], dim=-1), max_iterations=100,
            early_stopping_any_converged=True,
        )
        sol = solver.solve(pk.Transform3d(matrix=T_flange))
        out = []
        for b in range(T_flange.shape[0]):
            cand = sol.solutions[b]                               # (retries, 6)
            err = sol.err_pos[b] / pos_tol + sol.err_rot[b] / rot_tol
            if q_init is not None:
                order = torch.argsort(err.clamp_min(1.0) * 1e3 + (cand - seeds[0]).abs().sum(-1))
            else:
                order = torch.argsort(err)
            q_best, e_best = None, None
            for idx in order[:4].tolist():
                q, e = self._polish(cand[idx], T_flange[b])
                if q is not None:
                    q_best, e_best = q, e
                    break
                if e_best is None or e[0] + e[1] < e_best[0] + e_best[1]:
                    e_best = e
            if q_best is None:
                raise UnreachablePoseError(
                    f"no joint configuration reaches target {b} (best error {e_best[0] * 1e3:.3g} mm, "
                    f"{e_best[1] * 1e3:.3g} mrad; tolerance {pos_tol * 1e3:g} mm, {rot_tol * 1e3:g} mrad)")
            out.append(q_best)
        return torch.stack(out).reshape(*batch, 6)

    def _polish(self, q: torch.Tensor, T_flange: torch.Tensor, iters: int = 20):
        """Undamped Newton on the flange pose; returns (q or None, (pos_err, rot_err))."""
        lim = (self.lower, self.upper)
        for _ in range(iters):
            T = self.chain.forward_kinematics(q[None]).get_matrix()[0]
            e = pose_error(T_flange, T)
            ep, er = float(e[:3].norm()), float(e[3:].norm())
            if ep < 1e-10 and er < 1e-10:
                break
            J = self.chain.jacobian(q[None])[0]
            try:
                q = q + torch.linalg.solve(J, e)
            except RuntimeError:  # exactly singular: leave to the caller's next candidate
                break
        T = self.chain.forward_kinematics(q[None]).get_matrix()[0]
        e = pose_error(T_flange, T)
        ep, er = float(e[:3].norm()), float(e[3:].norm())
        # Revolute joints: bring every angle to the representative nearest 0 that is inside the limits.
        q = torch.remainder(q + math.pi, 2 * math.pi) - math.pi
        ok = ep <= 1e-5 and er <= 1e-5 and bool(((q >= lim[0]) & (q <= lim[1])).all())
        return (q if ok else None), (ep, er)

    def _step_single(self, q: torch.Tensor, dx: torch.Tensor, hold_orientation: bool) -> torch.Tensor | None:
        """:meth:`cartesian_step` of one joint vector `(6,)` outside autograd, in NumPy (:mod:`kinematics.single`);
        None where it does not apply (a rotation error over 90 degrees: the torch path's robust log takes it).

        A guarded motion repeats one small step many times (an approach, a press, a slide's sub-steps): the last
        joint step of the same Cartesian step starts the Newton iterations (one iteration then converges where two
        were needed), unless it starts further from the goal than the joints themselves."""
        q0 = q.detach().cpu().numpy().astype(np.float64)
        d = dx.detach().cpu().numpy().astype(np.float64)
        goal = self.forward_kinematics(q).detach().cpu().numpy().copy()
        goal[:3, 3] += d
        key = (hold_orientation, d.tobytes())
        warm = self._last_step[1] if self._last_step[0] == key else None
        lower, upper = self._limits_np
        q_k, T_k, converged = (q0 if warm is None else q0 + warm), None, False
        for i in range(self.newton_iterations + (warm is not None)):
            fr = single.frames(q_k, UR5_DH)
            T_k = fr[-1] @ self._T_flange_tool_np
            e = single.pose_error(goal, T_k)
            if e is None:
                return None
            if not hold_orientation:
                e = e[:3]
            if i == 0 and warm is not None and np.abs(e).max() > 0.5 * np.abs(d).max():
                q_k = q0                                          # a poor guess: start from the joints
                continue
            if np.abs(e).max() <= NEWTON_TOLERANCE:
                converged = True
                break
            J = single.jacobian(fr, T_k[:3, 3])
            if not hold_orientation:
                J = J[:3]
            q_k = q_k + single.dls_step(J, e, q_k, lower, upper, max_damping=self.max_damping,
                                        threshold=self.singular_threshold, limit_margin=self.limit_margin)
        dq = q_k - q0
        self._last_step = (key, dq)
        biggest = float(np.abs(dq).max())
        if converged and biggest <= self.max_joint_step:
            out = torch.as_tensor(q_k, dtype=self.dtype, device=self.device)
            # the last iteration's pose is the pose of the joints returned: the robot asks for it next
            self._keep_pose(self._pose_key(out, "tool"), torch.as_tensor(T_k, dtype=self.dtype, device=self.device))
            return out
        scale = self.max_joint_step / biggest if biggest > self.max_joint_step else 1.0
        return torch.as_tensor(q0 + dq * scale, dtype=self.dtype, device=self.device)

    def cartesian_step(
        self,
        q: torch.Tensor,
        dx: torch.Tensor,
        drot: torch.Tensor | None = None,
        *,
        hold_orientation: bool = True,
    ) -> torch.Tensor:
        """Joint positions after moving the fingertip by ``dx``: one damped-least-squares step.

        ``q_next = q + dq`` with ``dq`` from :func:`kinematics.ik.dls_step` on the fingertip Jacobian: adaptive
        damping near singularities, joints locked at their limits, and one uniform scale so that
        ``max |dq| <= max_joint_step``. The DLS step is repeated up to ``newton_iterations`` times towards the
        goal pose (``p(q) + dx``, orientation held), stopping once the pose error is below
        :data:`NEWTON_TOLERANCE`, so the realised displacement matches ``dx`` to ~1e-9 m for
        centimetre steps away from singularities and limits; near them the step is bounded but may fall
        short: callers that need exactness check ``position(q_next)`` (the robot backends do and refuse).

        Args:
            q: `(6,)` or `(B, 6)` joint positions [rad].
            dx: `(3,)` or `(B, 3)` fingertip displacement in the base frame [m].
            drot: optional `(3,)` / `(B, 3)` rotation vector to apply to the tool [rad], base frame.
            hold_orientation: keep the tool orientation (6-D task); if False only the position is
                controlled (3-D task, the extra freedom used to stay away from singularities).

        Returns:
            `(6,)` or `(B, 6)` next joint positions, differentiable w.r.t. ``q``, ``dx`` and ``drot``.
        """
        q = self._q(q)
        dx = torch.as_tensor(dx, dtype=self.dtype, device=self.device)
        if dx.shape[-1:] != (3,) or not bool(torch.isfinite(dx).all()):
            raise ValueError(f"dx must be finite with shape (..., 3) [m], got {tuple(dx.shape)}")
        single = q.dim() == 1
        qb, dxb = q.reshape(-1, 6), dx.reshape(-1, 3)
        B = max(qb.shape[0], dxb.shape[0])
        if qb.shape[0] not in (1, B) or dxb.shape[0] not in (1, B):
            raise ValueError(f"q {tuple(q.shape)} and dx {tuple(dx.shape)} have different batch sizes")
        qb, dxb = qb.expand(B, 6), dxb.expand(B, 3)
        if drot is not None and not hold_orientation:
            raise ValueError("drot needs hold_orientation=True")
        if B == 1 and drot is None and not (torch.is_grad_enabled() and (q.requires_grad or dx.requires_grad)):
            q_single = self._step_single(qb[0], dxb[0], hold_orientation)
            if q_single is not None:
                return q_single if single and dx.dim() == 1 else q_single[None]
        q_next = self._step_batch(qb, dxb, drot, hold_orientation)
        return q_next[0] if single and dx.dim() == 1 else q_next

    def _step_batch(self, qb: torch.Tensor, dxb: torch.Tensor, drot: torch.Tensor | None,
                    hold_orientation: bool) -> torch.Tensor:
        """:meth:`cartesian_step` of `(B, 6)` joints and `(B, 3)` steps in torch (batched, differentiable)."""
        B = qb.shape[0]
        T0 = self.forward_kinematics(qb)
        T_goal = T0.clone()
        T_goal[:, :3, 3] = T0[:, :3, 3] + dxb
        if drot is not None:
            w = torch.as_tensor(drot, dtype=self.dtype, device=self.device).reshape(-1, 3).expand(B, 3)
            T_goal[:, :3, :3] = pk.axis_angle_to_matrix(w) @ T0[:, :3, :3]
        q_k = qb
        for _ in range(self.newton_iterations):
            frames, T_k = self._frames_and_tool(q_k)
            e = pose_error(T_goal, T_k)
            if not hold_orientation:
                e = e[:, :3]
            # each joint vector stops once converged (a 1 mm step: after two iterations), so a batch gives each
            # member what it would get alone
            going = e.abs().amax(dim=-1, keepdim=True) > NEWTON_TOLERANCE
            if not bool(going.any()):
                break
            J = dh_jacobian(frames, T_k[:, :3, 3])
            if not hold_orientation:
                J = J[:, :3, :]
            dq = dls_step(J, e, q_k, self.lower, self.upper, max_damping=self.max_damping,
                          threshold=self.singular_threshold, max_joint_step=math.inf, limit_margin=self.limit_margin)
            q_k = q_k + torch.where(going, dq, torch.zeros_like(dq))
        dq = q_k - qb
        biggest = dq.abs().amax(dim=-1, keepdim=True)
        scale = torch.where(biggest > self.max_joint_step, self.max_joint_step / biggest.clamp_min(1e-300),
                            torch.ones_like(biggest))
        return qb + dq * scale
