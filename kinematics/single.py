"""One joint vector outside autograd, in NumPy: the arm's poses, Jacobians and Cartesian steps for a guarded motion.

A simulated guarded motion asks, every millimetre, for a few poses, a pose error, a Jacobian and a damped
least-squares step of one joint vector. On `(1, 6)` tensors each of those is a dozen or more torch operations of
10-40 us each, whatever the arithmetic: a millimetre cost ~2.5 ms of kinematics. The same arithmetic on NumPy arrays
and Python floats costs a tenth of it. :class:`kinematics.UR5` takes this path for one joint vector that needs no
gradient, and its torch functions (:func:`kinematics.dh.dh_forward`, :func:`kinematics.dh.dh_jacobian`,
:func:`kinematics.ur5.pose_error`, :func:`kinematics.ik.dls_step`) for batches and autograd; tests hold the two equal
to 1e-12. Same conventions as those: standard DH, base-frame geometric Jacobians, ``[dp, log(R_target R^T)]`` errors.
"""

from __future__ import annotations

import math

import numpy as np

from .dh import DHRow

__all__ = ["frames", "jacobian", "pose_error", "dls_step"]


def frames(q: np.ndarray, dh: tuple[DHRow, ...]) -> np.ndarray:
    """`(n, 4, 4)` DH frames ``T_base_frame_i`` of joints `(n,)` [rad] (as :func:`kinematics.dh.dh_forward`)."""
    out = np.empty((len(dh), 4, 4))
    T = None
    for i, (qi, r) in enumerate(zip(q.tolist(), dh)):
        c, s = math.cos(qi), math.sin(qi)
        ca, sa = math.cos(r.alpha), math.sin(r.alpha)
        A = np.array([[c, -s * ca, s * sa, r.a * c],
                      [s, c * ca, -c * sa, r.a * s],
                      [0.0, sa, ca, r.d],
                      [0.0, 0.0, 0.0, 1.0]])
        T = A if T is None else T @ A
        out[i] = T
    return out


def jacobian(fr: np.ndarray, point: np.ndarray) -> np.ndarray:
    """`(6, n)` geometric Jacobian of ``point`` `(3,)` [m, base] on the last link, from :func:`frames`."""
    z = np.concatenate([[[0.0, 0.0, 1.0]], fr[:-1, :3, 2]])       # joint i turns about frame i-1's z axis
    o = np.concatenate([[[0.0, 0.0, 0.0]], fr[:-1, :3, 3]])
    return np.concatenate([np.cross(z, point - o), z], axis=1).T


def so3_log(R: np.ndarray) -> np.ndarray | None:
    """Rotation vector of a `(3, 3)` rotation of less than 90 degrees (as :func:`kinematics.ur5._so3_log`); None for
    a larger one (the caller takes the torch function's robust branch)."""
    s = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    if not c > 0:
        return None
    s2 = float(s @ s)
    if s2 < 1e-12:
        return s * (1.0 + s2 / 6.0)
    sn = math.sqrt(s2)
    return s * (math.atan2(sn, c) / sn)


def pose_error(T_target: np.ndarray, T: np.ndarray) -> np.ndarray | None:
    """`(6,)` ``[p_target - p, log(R_target R^T)]`` of two `(4, 4)` poses; None for a rotation error over 90 deg."""
    w = so3_log(T_target[:3, :3] @ T[:3, :3].T)
    return None if w is None else np.concatenate([T_target[:3, 3] - T[:3, 3], w])


def dls_step(J: np.ndarray, v: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray, *,
             max_damping: float, threshold: float, limit_margin: float) -> np.ndarray:
    """`(n,)` damped least-squares joint step for `(r, n)` ``J`` and `(r,)` ``v`` at joints `(n,)`, with the joint
    locking of :func:`kinematics.ik.dls_step` (adaptive damping, joints that would leave their limits locked and
    the step solved again), without a joint-step limit."""
    free = np.ones(len(q), dtype=bool)
    r = J.shape[0]
    for _ in range(len(q) + 1):
        Jf = J * free
        s_min = np.linalg.svd(Jf, compute_uv=False)[-1]
        lam2 = max_damping ** 2 * (1.0 - min(s_min / threshold, 1.0) ** 2)
        A = Jf @ Jf.T + lam2 * np.eye(r)
        try:
            L = np.linalg.cholesky(A)
            w = np.linalg.solve(L.T, np.linalg.solve(L, v))
        except np.linalg.LinAlgError:
            w = np.linalg.pinv(A) @ v
        dq = Jf.T @ w
        q_new = q + dq
        newly = (((q_new > upper - limit_margin) & (dq > 0)) | ((q_new < lower + limit_margin) & (dq < 0))) & free
        if not newly.any():
            break
        free &= ~newly
    return dq
