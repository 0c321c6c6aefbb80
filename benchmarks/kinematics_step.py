"""The kinematics of a guarded motion's millimetre: one joint vector's pose, Jacobian and Cartesian step, three ways.

A simulated approach or slide asks, every millimetre, for poses, a Jacobian and one damped least-squares Cartesian
step of one joint vector (``UR5.cartesian_step``). Timed here on the same inputs, one thread:

* one pose and Jacobian: pytorch-kinematics' chain (``chain.forward_kinematics`` + ``chain.jacobian``, what
  ``UR5`` used before), the closed-form DH frames in torch (``kinematics.dh.dh_forward`` + ``dh_jacobian``, the
  batched and differentiable path), and in NumPy (``kinematics.single``, one joint vector without a gradient);
* 200 repeated 1 mm steps along a line (an approach): the torch path (``UR5._step_batch``, a batch of one, cold
  started) against the NumPy path (``UR5._step_single``, warm-started from the last joint step), with the largest
  difference of the joints they reach.

    python benchmarks/kinematics_step.py
"""

from __future__ import annotations

import platform
import time

import torch

from kinematics import UR5, single
from kinematics.dh import UR5_DH, dh_forward, dh_jacobian


def per_call(f, n: int) -> float:
    """Mean seconds per call of ``f`` over ``n`` calls (after one warm-up call)."""
    f()
    t0 = time.perf_counter()
    for _ in range(n):
        f()
    return (time.perf_counter() - t0) / n


def main() -> None:
    torch.set_num_threads(1)
    ur5 = UR5(tool_offset=(0.0, 0.0, 0.05))
    q = torch.tensor([[0.7, -1.6, 1.1, -1.0, -1.2, 0.4]], dtype=torch.float64)
    q_np = q[0].numpy()
    print(f"{platform.processor() or platform.machine()}, torch {torch.__version__}, 1 thread\n")

    def chain():
        ur5.chain.forward_kinematics(q).get_matrix()
        ur5.chain.jacobian(q, locations=ur5.tool_offset)

    def dh_torch():
        fr = dh_forward(q, UR5_DH)
        dh_jacobian(fr, (fr[:, -1] @ ur5.T_flange_tool)[:, :3, 3])

    def dh_numpy():
        fr = single.frames(q_np, UR5_DH)
        single.jacobian(fr, (fr[-1] @ ur5._T_flange_tool_np)[:3, 3])

    with torch.no_grad():
        rows = [("pytorch-kinematics chain", per_call(chain, 300)), ("DH frames, torch", per_call(dh_torch, 300)),
                ("DH frames, NumPy (one vector)", per_call(dh_numpy, 300))]
        print("| one pose and Jacobian | time [us] | ratio to the chain |\n|---|---|---|")
        for name, t in rows:
            print(f"| {name} | {t * 1e6:.0f} | {rows[0][1] / t:.1f} |")

        dx = torch.tensor([0.0006, -0.0003, -0.0007], dtype=torch.float64)
        dx = dx / dx.norm() * 1e-3
        n = 200

        def line(step):
            qk = q[0].clone()
            for _ in range(n):
                qk = step(qk)
            return qk

        torch_end = line(lambda qk: ur5._step_batch(qk[None], dx[None], None, True)[0])
        numpy_end = line(lambda qk: ur5._step_single(qk, dx, True))
        t_torch = per_call(lambda: line(lambda qk: ur5._step_batch(qk[None], dx[None], None, True)[0]), 3) / n
        t_numpy = per_call(lambda: line(lambda qk: ur5._step_single(qk, dx, True)), 3) / n
    print(f"\n| {n} Cartesian steps of 1 mm | time per step [us] |\n|---|---|")
    print(f"| torch (a batch of one, cold start) | {t_torch * 1e6:.0f} |")
    print(f"| NumPy (one vector, warm start) | {t_numpy * 1e6:.0f} |")
    print(f"\nratio torch / NumPy: {t_torch / t_numpy:.1f}; the joints reached after {n} mm differ by "
          f"{float((torch_end - numpy_end).abs().max()):.1e} rad")


if __name__ == "__main__":
    main()
