"""The product each planning step pays with many camera points: a few kernel rows times the outer basis U.

An append of one contact and 4 free-space points multiplies 8 rows (5 kernel rows and the contact's 3 derivative
rows) by U, `(N_o, r)`: with N_o = 10,000 that reads 250 MB (truncated basis, r ~ 3100) to 800 MB (exact, r =
N_o). This times that product with U stored row-major and column-major (torch, i.e. MKL here), with numpy's
OpenBLAS for comparison, against the time to merely read U once (a sum): the floor any kernel has.

    OMP_NUM_THREADS=1 python benchmarks/small_gemm.py
"""

from __future__ import annotations

import argparse
import platform
import time

import torch


def _median_ms(f, repeat: int = 9) -> float:
    f()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return 1e3 * sorted(times)[len(times) // 2]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shapes", nargs="+", default=["10000x3096", "20000x3253", "10000x10000"],
                        help="N_o x r of U (the truncated basis at outer_tol 1e-3 on planning_step.py's data, and "
                             "the exact engine)")
    parser.add_argument("--rows", type=int, default=8)
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(f"{platform.processor() or platform.machine()}, torch {torch.__version__} "
          f"(BLAS: {'MKL' if torch.backends.mkl.is_available() else 'other'}), 1 thread")
    print("| N_o x r | read U once [ms] | row-major U [ms] | column-major U [ms] | ratio row / column | "
          "numpy (OpenBLAS), row-major [ms] |")
    print("|---|---|---|---|---|---|")
    for shape in args.shapes:
        n, r = (int(v) for v in shape.split("x"))
        g = torch.Generator().manual_seed(0)
        u_row = torch.randn(n, r, dtype=torch.float64, generator=g)
        u_col = u_row.T.contiguous().T
        rows = torch.randn(args.rows, n, dtype=torch.float64, generator=g)
        assert torch.allclose(rows @ u_row, rows @ u_col, rtol=0, atol=1e-9)
        t_read = _median_ms(lambda: u_row.sum())
        t_row = _median_ms(lambda: rows @ u_row)
        t_col = _median_ms(lambda: rows @ u_col)
        rn, un = rows.numpy(), u_row.numpy()
        t_np = _median_ms(lambda: rn @ un)
        print(f"| {n} x {r} | {t_read:.1f} | {t_row:.1f} | {t_col:.1f} | {t_row / t_col:.2f} | {t_np:.1f} |",
              flush=True)


if __name__ == "__main__":
    main()
