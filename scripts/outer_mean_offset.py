"""Does an outer-task prior mean of ``1 - g / ramp`` (``GPIOIS.set_outer_mean``), with ``g`` the cover's gap that the
touches measure (``cover_gap``), bring finished runs' estimates closer? On their final data.

For each log of a study of ``examples/scenes/real/*.toml``: the run's final data with its logged K_t and outer mean
(``base``), and with the outer mean set from the gap the run's contacts measure and K_t re-learned from every start
(``outer mean``); each measured as the studies measure (``Scene3D.measure``: Hausdorff, Chamfer, F-score at 1 cm,
bias). docs/method-notes.md section 15 reports what it printed on the force-field wide covers' runs made before the
library set the mean itself.

    python scripts/outer_mean_offset.py outputs/real_ff_wide_judged/logs/*visual-tactile*
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from inner_mean_offset import _row, final_state  # noqa: E402  (scripts/ is not a package)
from torch_gpioius.exploration.observations import ObservationPolicy, cover_gap  # noqa: E402


def main(paths: list[str]) -> None:
    warnings.simplefilter("ignore")
    torch.set_num_threads(1)
    ramp = ObservationPolicy().ramp
    for path in paths:
        run, scene, model, data, contacts = final_state(path)
        gap = cover_gap(contacts, data.x[(data.task == 1) & (data.y == 0)], reach=0.02)
        out = [_row(f"base (outer mean {model.outer_mean:.2f})", scene, model, contacts)]
        if gap == gap:                                     # NaN: too few contacts under seen cover
            model.set_outer_mean(1.0 - gap / ramp).fit(multi_start=True)
            out.append(_row(f"outer mean {model.outer_mean:.2f} (gap {gap * 100:.1f} cm)", scene, model, contacts))
        print(run.path.stem, " | ".join(out), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
