"""Would a transfer that knows the cover's gap carry the camera's shape onto the body better than one K_t? On
finished runs' final data (the offline first step of the transfer work; docs/method-notes.md section 16).

The paper's model says ``F_out - 1 = r (F_in - 1)`` through one task covariance K_t times one spatial kernel. A cover
that stands off the body by a gap g(x) is, in label units, the inner field shifted by ``g(x) / ramp``: not a scaled
copy of it. For each visual-tactile log of a study (an object of a set, or a scene file of ``--scenes``), the run's own
final model (``base``, its logged K_t) against one variant fitted on the same final data, each measured by the
converged ruler (``world.measure``). The variants:

* default: an offset field of the outer task alone (a linear model of coregionalization of two scales),
  ``cov = k(x, x') K_t[t, t'] + s k_L(x, x') [t = t' = 1]``, the means 1 (inner) and ``m_out`` (outer), K_t, ``s``,
  ``L`` and ``m_out`` learned by the exact marginal likelihood (dense Cholesky, L-BFGS from three starts);
  ``--fixed-mean`` holds ``m_out`` at 1, ``--no-field`` drops the field, ``--linear-mean`` makes ``m_out`` linear in x,
  ``--relabel`` labels the camera's free-space points by their distance from the seen surface;
* ``--gap-mean``: the library's model with the outer mean ``1 - gap / ramp``, the gap the run's contacts measure
  (``ObservationPolicy.cover_offset`` applied at the end), K_t re-learned; ``--camera-inside`` puts back the camera's
  observations as first captured (the inside points the gap retracted), ``--deeper D ...`` adds inside points at those
  depths [m] along each one's inward direction labelled ``-D / ramp`` (the outer field a signed distance down to the
  gap; one that comes within 0.9 D of a seen point is dropped), ``--mean-one`` keeps the paper's one mean.

Prints a row per run and the paired medians.

    python scripts/offset_field.py outputs/bench61/primitives-wide/logs/*visual-tactile* \
        --gap-mean --camera-inside --deeper 0.04 0.06
"""

from __future__ import annotations

import argparse
import math
import sys
import types
import warnings
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from worst_errors import visual_tactile_finals  # noqa: E402  (scripts/ is not a package)


def _matern52(x: torch.Tensor, z: torch.Tensor, length: torch.Tensor) -> torch.Tensor:
    r = torch.cdist(x, z).clamp_min(0.0) / length
    s5 = math.sqrt(5.0) * r
    return (1.0 + s5 + 5.0 / 3.0 * r * r) * torch.exp(-s5)


class OffsetField:
    """The two-scale outer-task model on one run's final data (dense, exact)."""

    def __init__(self, model, length_factor: float = 4.0, relabel: bool = False, learn_mean: bool = True,
                 max_length: float = 0.3, field: bool = True, linear: bool = False, mean0: float = 1.0):
        self.base = model
        self.mean0 = mean0
        self.x = model.train_inputs[0].detach()
        self.y = model.train_targets.detach().clone()
        self.t = model.train_task.detach()
        self.learn_mean, self.max_length, self.field, self.linear = learn_mean, max_length, field, linear
        self.centre = self.x[self.t == 1].mean(dim=0)
        if relabel:
            # the camera's free-space points as signed distances: the distance to the nearest seen point over the ramp
            from scipy.spatial import cKDTree

            from torch_gpioius.exploration.observations import ObservationPolicy

            x, y, t = self.x.numpy(), self.y.numpy(), self.t.numpy()
            seen = x[(t == 1) & (y == 0)]
            free = (t == 1) & (y > 0)
            d = cKDTree(seen).query(x[free])[0]
            self.y[torch.as_tensor(free)] = torch.as_tensor(d / ObservationPolicy().ramp)
        self.noise = float(model.noise)
        self.k = model.covar_module.value(self.x, self.x).detach()
        self.length0 = float(model.covar_module.length) * length_factor
        self.outer = (self.t == 1).double()

    def _parts(self, p: torch.Tensor):
        l00, l10, l11, log_s, log_l, m_out = p[:6]
        chol = torch.stack([torch.stack([torch.exp(l00), torch.zeros((), dtype=p.dtype)]),
                            torch.stack([l10, torch.exp(l11)])])
        kt = chol @ chol.T
        length = self.max_length * torch.sigmoid(log_l)
        s = torch.exp(log_s) if self.field else torch.zeros((), dtype=p.dtype)
        return kt, s, length, (m_out if self.learn_mean else torch.full((), self.mean0, dtype=p.dtype))

    def outer_mean(self, p: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        m = self._parts(p)[3] * torch.ones(len(x), dtype=x.dtype)
        return m + (x - self.centre) @ p[6:9] if self.linear else m

    def gram(self, p: torch.Tensor) -> torch.Tensor:
        kt, s, length, _ = self._parts(p)
        g = self.k * kt[self.t][:, self.t]
        g = g + s * _matern52(self.x, self.x, length) * (self.outer[:, None] * self.outer[None, :])
        return g + self.noise * torch.eye(len(self.x), dtype=self.x.dtype)

    def residual(self, p: torch.Tensor) -> torch.Tensor:
        return self.y - torch.where(self.t == 0, torch.ones_like(self.y), self.outer_mean(p, self.x))

    def nll(self, p: torch.Tensor) -> torch.Tensor:
        chol = torch.linalg.cholesky(self.gram(p))
        r = self.residual(p).unsqueeze(-1)
        a = torch.cholesky_solve(r, chol)
        return 0.5 * (r * a).sum() + torch.log(torch.diagonal(chol)).sum()

    def fit(self, starts=None) -> "OffsetField":
        kt0 = self.base.task_covariance.detach()
        c0 = torch.linalg.cholesky(kt0 + 1e-6 * torch.eye(2, dtype=kt0.dtype))
        base = [math.log(float(c0[0, 0])), float(c0[1, 0]), math.log(max(float(c0[1, 1]), 1e-3))]
        starts = starts or ([(0.1, 1.0), (0.5, 0.2), (0.05, 0.6)] if self.mean0 == 1.0 else
                            [(0.1, self.mean0), (0.02, self.mean0), (0.5, self.mean0)])
        best = None
        for s0, m0 in starts:
            frac = min(self.length0 / self.max_length, 0.9)
            p = torch.tensor(base + [math.log(s0), math.log(frac / (1 - frac)), m0, 0.0, 0.0, 0.0],
                             dtype=torch.float64, requires_grad=True)
            opt = torch.optim.LBFGS([p], lr=0.5, max_iter=200, line_search_fn="strong_wolfe")

            def closure():
                opt.zero_grad()
                v = self.nll(p)
                v.backward()
                return v

            try:
                opt.step(closure)
                v = float(self.nll(p))
            except (RuntimeError, torch.linalg.LinAlgError):
                continue
            if math.isfinite(v) and (best is None or v < best[0]):
                best = (v, p.detach().clone())
        if best is None:
            raise RuntimeError("no start converged")
        self.nll_value, self.p = best
        kt, s, length, m_out = self._parts(self.p)
        self.kt, self.s, self.length, self.m_out = kt, float(s), float(length), float(m_out)
        chol = torch.linalg.cholesky(self.gram(self.p))
        self.alpha = torch.cholesky_solve(self.residual(self.p).unsqueeze(-1), chol).squeeze(-1)
        self.chol = chol
        return self

    def as_model(self):
        """The base model with its inner prediction replaced by this one's (what the ruler measures)."""
        model = self.base
        weights = (self.kt[0][self.t] * self.alpha).detach()
        kern = model.covar_module

        def _predict_mean(this, xq, task):
            if task != 0:
                raise NotImplementedError("the inner task only")
            return 1.0 + kern.value(xq, self.x) @ weights

        def _predict(this, xq, task):
            mean = _predict_mean(this, xq, task)
            kx = kern.value(xq, self.x) * self.kt[0][self.t]
            v = torch.cholesky_solve(kx.T, self.chol)
            var = self.kt[0, 0] * kern.value(xq[:1], xq[:1])[0, 0] - (kx * v.T).sum(-1)
            return mean, var.clamp_min(0.0)

        model._predict_mean = types.MethodType(_predict_mean, model)
        model._predict = types.MethodType(_predict, model)
        model._engine = None
        return model

    def correlation(self) -> float:
        return float(self.kt[0, 1] / torch.sqrt(self.kt[0, 0] * self.kt[1, 1]))


def _row(measured) -> dict:
    if not measured.estimate:
        return {"chamfer": math.inf, "hausdorff": math.inf, "fscore_10mm": 0.0, "bias": math.nan}
    return {"chamfer": measured.shape["chamfer"], "hausdorff": measured.hausdorff,
            "fscore_10mm": measured.shape["fscore_10mm"], "bias": measured.shape["bias"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("logs", nargs="+", type=Path)
    parser.add_argument("--scenes", type=Path, default=Path("examples/scenes/real"))
    parser.add_argument("--length-factor", type=float, default=4.0,
                        help="the offset field's starting length, in the kernel's lengths")
    parser.add_argument("--max-length", type=float, default=0.3, help="the offset field's longest length [m]")
    parser.add_argument("--relabel", action="store_true",
                        help="the camera's free-space points labelled by their distance from the seen surface")
    parser.add_argument("--fixed-mean", action="store_true", help="the outer mean held at 1")
    parser.add_argument("--no-field", action="store_true", help="no offset field (the outer mean alone)")
    parser.add_argument("--linear-mean", action="store_true", help="the outer mean linear in x")
    parser.add_argument("--camera-inside", action="store_true",
                        help="with --gap-mean: the camera's observations as first captured (their inside points "
                             "before the gap retracted them) with the final contacts")
    parser.add_argument("--deeper", type=float, nargs="*", default=[],
                        help="with --camera-inside: more inside points at these depths [m], labelled by them")
    parser.add_argument("--mean-one", action="store_true",
                        help="with --gap-mean: the outer mean left at 1 (the data changed, K_t re-learned)")
    parser.add_argument("--field", action="store_true",
                        help="with --gap-mean: the offset field of the outer task on top of the gap's mean (its outer "
                             "mean starting at 1 - gap / ramp, held there with --fixed-mean)")
    parser.add_argument("--gap-mean", action="store_true",
                        help="instead: the library's model with the outer mean 1 - gap / ramp, the gap the contacts "
                             "measure (ObservationPolicy.cover_offset at the end of a run), K_t re-learned")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    torch.set_num_threads(1)
    rows = []
    for log, run, world, model, data in visual_tactile_finals(args.logs, args.scenes):
        contacts = data.x[(data.task == 0) & (data.y == 0)]
        base = _row(world.measure(model, contacts))
        rho = model.correlation
        if args.gap_mean:
            from torch_gpioius.exploration.observations import ObservationPolicy, cover_gap

            gap = cover_gap(contacts, data.x[(data.task == 1) & (data.y == 0)], reach=0.02)
            variant = dict(base)
            if args.camera_inside:
                from torch_gpioius.io.datasets import replay
                from torch_gpioius.models.gpiois import GPIOIS

                first = next(ds for _, ds in replay(log) if (ds.task == 1).any())
                inner, outer = data.task == 0, first.task == 1
                ox, oy = first.x[outer], first.y[outer]
                if args.deeper:
                    # more inside points along each one's inward direction, labelled by their depth: the outer
                    # field a signed distance down to the gap; one that comes near another seen point is dropped
                    from scipy.spatial import cKDTree

                    seen = ox[oy == 0]
                    behind = ox[oy < 0]
                    _, j = cKDTree(seen).query(behind)
                    step = behind - seen[j]
                    depth0 = np.linalg.norm(step, axis=1)
                    extra_x, extra_y = [], []
                    for k in args.deeper:
                        pts = seen[j] + step * (k / depth0)[:, None]
                        ok = cKDTree(seen).query(pts)[0] >= 0.9 * k
                        extra_x.append(pts[ok])
                        extra_y.append(np.full(int(ok.sum()), -k / ObservationPolicy().ramp))
                    ox, oy = np.r_[ox, *extra_x], np.r_[oy, *extra_y]
                model = GPIOIS(np.r_[data.x[inner], ox], np.r_[data.y[inner], oy],
                               np.r_[data.task[inner], np.ones(len(oy), np.int64)], noise=float(model.noise),
                               kernel=run.kernel())
            if args.mean_one:                              # the paper's one mean: K_t alone re-learned
                model.fit(multi_start=True)
                variant = _row(world.measure(model, contacts))
            elif gap == gap:                               # NaN: too few contacts under the seen cover
                model.set_outer_mean(1.0 - gap / ObservationPolicy().ramp).fit(multi_start=True)
                variant = _row(world.measure(model, contacts))
                if args.field:                             # the offset field on top of the gap's mean
                    field = OffsetField(model, args.length_factor, False, not args.fixed_mean, args.max_length,
                                        mean0=model.outer_mean).fit()
                    gapped = variant
                    variant = _row(world.measure(field.as_model(), contacts))
                    print(f"    gap mean alone Ch {gapped['chamfer'] * 100:.2f}; field s {field.s:.3f} "
                          f"L {field.length * 100:.1f} cm m_out {field.m_out:.2f} rho {field.correlation():.2f}")
            rows.append((base, variant))
            print(f"{log.stem}: base Ch {base['chamfer'] * 100:.2f} rho {rho:.2f} | gap {gap * 100:.1f} cm, outer mean "
                  f"{model.outer_mean:.2f}: Ch {variant['chamfer'] * 100:.2f} H {variant['hausdorff'] * 100:.1f} "
                  f"F1 {variant['fscore_10mm']:.2f} bias {variant['bias'] * 100:+.2f} rho {model.correlation:.2f}",
                  flush=True)
            continue
        field = OffsetField(model, args.length_factor, args.relabel, not args.fixed_mean, args.max_length,
                            not args.no_field, args.linear_mean).fit()
        variant = _row(world.measure(field.as_model(), contacts))
        rows.append((base, variant))
        print(f"{log.stem}: n {len(field.y)} | base Ch {base['chamfer'] * 100:.2f} H {base['hausdorff'] * 100:.1f} "
              f"rho {rho:.2f} | field Ch {variant['chamfer'] * 100:.2f} H {variant['hausdorff'] * 100:.1f} "
              f"F1 {variant['fscore_10mm']:.2f} bias {variant['bias'] * 100:+.2f} rho {field.correlation():.2f} "
              f"s {field.s:.3f} L {field.length * 100:.1f} cm m_out {field.m_out:.2f} "
              f"slope {field.p[6:9].numpy().round(2)}", flush=True)
    if rows:
        b = np.array([r[0]["chamfer"] for r in rows]) * 100
        v = np.array([r[1]["chamfer"] for r in rows]) * 100
        print(f"{len(rows)} runs: median Chamfer base {np.median(b):.2f} cm, field {np.median(v):.2f} cm; field closer "
              f"on {(v < b).sum()} of {len(rows)}; median paired difference {np.median(v - b):+.2f} cm")


if __name__ == "__main__":
    main()
