"""Differentiable damped-least-squares (DLS) Cartesian steps.

pytorch-kinematics' IK solvers run under ``torch.no_grad`` and solve for poses, not for one differentiable
step; the planner needs ``dq(dx)`` with gradients, so this small kernel is ours. Pure functions on tensors;
:class:`kinematics.UR5` wraps them with its chain.
"""

from __future__ import annotations

import torch

__all__ = ["adaptive_damping", "dls_solve", "dls_step"]


def adaptive_damping(J: torch.Tensor, max_damping: float, threshold: float) -> torch.Tensor:
    """Damping that grows only near a singularity (Nakamura & Hanafusa; Chiaverini 1997).

    ``lambda^2 = max_damping^2 · (1 - (s_min / threshold)^2)`` when the smallest singular value ``s_min`` of
    ``J`` is below ``threshold``, else 0. Away from singularities the step is then the exact pseudo-inverse
    step; at a singularity the joint step is bounded by ``|v| / (2 · max_damping)``.

    Args:
        J: `(..., r, n)` Jacobians.
        max_damping: damping at an exact singularity, in the units of ``J``'s singular values.
        threshold: singular value below which damping starts.

    Returns:
        `(...)` squared damping ``lambda^2``.
    """
    s_min = torch.linalg.svdvals(J)[..., -1]
    ratio = (s_min / threshold).clamp(max=1.0)
    return max_damping**2 * (1.0 - ratio**2)


def dls_solve(J: torch.Tensor, v: torch.Tensor, lam2: torch.Tensor) -> torch.Tensor:
    """``dq = J^T (J J^T + lambda^2 I)^-1 v``, the minimiser of ``|J dq - v|^2 + lambda^2 |dq|^2``.

    Args:
        J: `(..., r, n)` Jacobians.
        v: `(..., r)` task-space velocities (or small displacements).
        lam2: `(...)` squared damping.

    Returns:
        `(..., n)` joint steps.
    """
    r = J.shape[-1 - 1]
    A = J @ J.transpose(-1, -2) + lam2[..., None, None] * torch.eye(r, dtype=J.dtype, device=J.device)
    # A is SPD when lambda > 0 or J has full row rank; cholesky_ex + solve stays differentiable and never
    # returns NaN silently: a failure falls back to the (least-squares) pseudo-inverse solve.
    L, info = torch.linalg.cholesky_ex(A)
    if bool((info == 0).all()):
        w = torch.cholesky_solve(v[..., None], L)[..., 0]
    else:
        w = (torch.linalg.pinv(A) @ v[..., None])[..., 0]
    return (J.transpose(-1, -2) @ w[..., None])[..., 0]


def dls_step(
    J: torch.Tensor,
    v: torch.Tensor,
    q: torch.Tensor,
    lower: torch.Tensor,
    upper: torch.Tensor,
    *,
    max_damping: float,
    threshold: float,
    max_joint_step: float,
    limit_margin: float,
) -> torch.Tensor:
    """One DLS joint step with joint-limit locking and a joint-delta limit.

    1. ``dq`` from :func:`dls_solve` with :func:`adaptive_damping`.
    2. Joint limits: any joint whose ``q + dq`` would leave ``[lower + margin, upper - margin]`` while moving
       outward is *locked* (its Jacobian column zeroed) and the step is re-solved with the remaining joints;
       repeated until no new joint locks (at most ``n`` passes). The task is then met as far as the free
       joints allow; callers compare the achieved with the requested motion.
    3. Joint-delta limit: if ``max |dq| > max_joint_step`` the whole step is scaled by one factor, so the
       Cartesian direction is kept to first order (never clipped per joint, which would change it).

    Args:
        J: `(B, r, n)` Jacobians at ``q``.
        v: `(B, r)` requested task-space displacement.
        q: `(B, n)` joint positions [rad].
        lower, upper: `(n,)` joint limits [rad].
        max_damping, threshold: see :func:`adaptive_damping`.
        max_joint_step: largest joint change in one step [rad].
        limit_margin: distance kept from a joint limit [rad].

    Returns:
        `(B, n)` joint steps, differentiable w.r.t. ``J``, ``v`` (and so ``q``) almost everywhere.
    """
    free = torch.ones_like(q, dtype=torch.bool)
    for _ in range(q.shape[-1] + 1):
        Jf = J * free[:, None, :].to(J.dtype)
        dq = dls_solve(Jf, v, adaptive_damping(Jf, max_damping, threshold))
        q_new = q + dq
        hits = ((q_new > upper - limit_margin) & (dq > 0)) | ((q_new < lower + limit_margin) & (dq < 0))
        newly = hits & free
        if not bool(newly.any()):
            break
        free = free & ~newly
    if max_joint_step == float("inf"):
        return dq
    biggest = dq.abs().amax(dim=-1, keepdim=True)
    scale = torch.where(biggest > max_joint_step, max_joint_step / biggest.clamp_min(1e-300),
                        torch.ones_like(biggest))
    return dq * scale
