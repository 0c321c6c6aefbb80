"""Wall time of a sweep: sequential in-process against Ray with 1 and 2 workers, in one run.

The workload is a small 2-D sweep (objects A and B, both modes, ``--seeds`` seeds, ``--max-steps`` steps per run),
each arrangement into a fresh folder. Every Ray worker pins torch to one thread. Prints the wall time of each
arrangement, the speed-up of 2 workers over sequential, and checks that the per-run results agree (each run is
deterministic given its seed, wherever it runs).

    python benchmarks/sweep_workers.py            # about 3 minutes on 2 cores
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

from torch_gpioius.studies.study import run_sweep


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--max-steps", type=int, default=40)
    args = parser.parse_args()
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs")
    print("| arrangement | runs | wall time [s] | speed-up over sequential |")
    print("|---|---|---|---|")
    finals, base = {}, None
    for label, kw in (("sequential, in-process (1 thread)", {"backend": "local", "workers": 1}),
                      ("Ray, 1 worker", {"backend": "ray", "workers": 1}),
                      ("Ray, 2 workers", {"backend": "ray", "workers": 2})):
        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            res = run_sweep("2d", objects=["A", "B"], seeds=args.seeds, out=tmp, max_steps=args.max_steps,
                            progress=False, **kw)
            wall = time.perf_counter() - t
            base = base or wall
            runs = [json.loads(p.read_text()) for p in Path(tmp, "runs").glob("*.json")]
            finals[label] = sorted((r["object"], r["mode"], r["seed"], r["series"]["hausdorff"][-1]) for r in runs)
        print(f"| {label} | {res['runs']} | {wall:.1f} | {base / wall:.2f}x |", flush=True)
    same = len({json.dumps(v) for v in finals.values()}) == 1
    print(f"\nper-run final Hausdorff distances {'agree' if same else 'DIFFER'} across the arrangements")


if __name__ == "__main__":
    main()
