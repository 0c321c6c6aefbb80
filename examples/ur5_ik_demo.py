"""Move the simulated UR5's fingertip along a planned Cartesian path and plot the joint trajectory.

The path is what the exploration produces: a sequence of 1 cm tangential steps on a surface, here a 10 cm
circle in a horizontal plane followed by a 3 cm dip, in the robot base frame. Every step goes through the
differentiable DLS IK step (``UR5.cartesian_step``) and the safety gate of the simulated robot. A last
command deliberately asks for a 5 cm jump: the gate refuses it and the robot does not move.

Run:  python examples/ur5_ik_demo.py [--out DIR]   (a few seconds; CI=1 makes the path shorter)
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import torch  # noqa: E402

from kinematics import UR5, UR5_JOINT_NAMES, SafetyViolation, SimulatedUR5  # noqa: E402

SMOKE = "CI" in os.environ


def planned_path(p0: torch.Tensor, n_circle: int, step: float = 0.01) -> torch.Tensor:
    """`(k, 3)` waypoints [m, base]: a circle of radius 5 cm through p0, then a 3 cm dip."""
    r = 0.05
    center = p0 + torch.tensor([r, 0.0, 0.0], dtype=torch.float64)
    ang = torch.linspace(math.pi, math.pi + 2 * math.pi * n_circle / 32, n_circle + 1, dtype=torch.float64)
    circle = center + r * torch.stack([torch.cos(ang), torch.sin(ang), torch.zeros_like(ang)], dim=-1)
    dip = circle[-1] - torch.arange(1, 4, dtype=torch.float64)[:, None] * torch.tensor([0.0, 0.0, step],
                                                                                      dtype=torch.float64)
    return torch.cat([circle, dip])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("outputs/ur5_ik_demo"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    ur5 = UR5(tool_offset=(0.0, 0.0, 0.05))                     # 5 cm fingertip on the flange
    q0 = torch.tensor([0.0, -1.2, 1.5, -1.9, -1.57, 0.0], dtype=torch.float64)
    robot = SimulatedUR5(ur5, q0)
    path = planned_path(robot.tool_position(), 8 if SMOKE else 32)
    reached = [robot.tool_position()]
    for target in path[1:]:
        robot.move_cartesian(target - robot.tool_position(), speed=0.05)
        reached.append(robot.tool_position())
    reached = torch.stack(reached)
    err = (reached - path).norm(dim=-1)
    try:
        robot.move_cartesian(torch.tensor([0.05, 0.0, 0.0], dtype=torch.float64))
        refused = "NOT refused"
    except SafetyViolation as exc:
        refused = f"refused: {exc}"
    times, qs = robot.trajectory()
    print(f"{len(path) - 1} steps, {float(times[-1]):.2f} s simulated, max tracking error {float(err.max()):.2e} m")
    print(f"5 cm jump {refused}")

    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for j, name in enumerate(UR5_JOINT_NAMES):
        ax[0].plot(times.numpy(), qs[:, j].numpy(), ".-", ms=3, label=name)
    ax[0].set(xlabel="simulated time [s]", ylabel="joint position [rad]", title="UR5 joint trajectory")
    ax[0].legend(fontsize=7, ncol=2, loc="center right")
    ax[1].plot(path[:, 0].numpy(), path[:, 1].numpy(), "k--", label="planned")
    ax[1].plot(reached[:, 0].numpy(), reached[:, 1].numpy(), "o", ms=3, label="fingertip (FK of executed joints)")
    ax[1].set(xlabel="x [m] (base)", ylabel="y [m] (base)", title="fingertip path, top view", aspect="equal")
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(args.out / "ur5_ik_demo.png", dpi=120)
    print(f"wrote {args.out / 'ur5_ik_demo.png'}")


if __name__ == "__main__":
    main()
