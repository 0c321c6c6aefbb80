"""Examples run in CI in their smoke form (CI=1), as a user would run them."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_example(script: str, out: Path) -> subprocess.CompletedProcess:
    """Run ``examples/<script> --out OUT`` with CI=1 (the smoke switch), as a user would; assert it succeeds."""
    result = subprocess.run([sys.executable, str(ROOT / "examples" / script), "--out", str(out)],
                            capture_output=True, text=True, env=dict(os.environ, CI="1"), timeout=300)
    assert result.returncode == 0, result.stderr
    return result


def test_fit_two_shapes_example(tmp_path):
    out = run_example("fit_two_shapes.py", tmp_path)
    assert (tmp_path / "fit_two_shapes.png").stat().st_size > 0
    lines = {line.split()[0]: line for line in out.stdout.splitlines() if line.startswith(("A ", "D "))}
    # the printed similarity table has both pairs and all four observation sets
    assert set(lines) == {"A", "D"}
    assert all(line.count("rho") == 4 for line in lines.values())


def test_ur5_ik_demo_example(tmp_path):
    out = run_example("ur5_ik_demo.py", tmp_path)
    assert (tmp_path / "ur5_ik_demo.png").stat().st_size > 0
    err = float(out.stdout.split("max tracking error ")[1].split()[0])
    assert err < 1e-6 and "5 cm jump refused" in out.stdout


def test_fit_logged_example(tmp_path):
    out = run_example("fit_logged.py", tmp_path)
    assert (tmp_path / "model.pt").stat().st_size > 0 and "CSV round trip" in out.stdout
    assert "(inside < 0)" in out.stdout and float(out.stdout.split("mu_in at (0, 0) = ")[1].split()[0]) < 0


def test_example_dataset_is_what_the_script_generates(tmp_path):
    """The shipped file is reproducible from the script (its observations; timings differ)."""
    import numpy as np

    import torch_gpioius as tg

    out = tmp_path / "ex.gpioius"
    subprocess.run([sys.executable, str(ROOT / "scripts" / "make_example_dataset.py"), "--out", str(out)],
                   check=True, capture_output=True, timeout=300)
    a, b = tg.load_dataset(out), tg.load_dataset(ROOT / "data" / "example_2d.gpioius")
    assert np.allclose(a.x, b.x, atol=1e-12) and (a.y == b.y).all() and (a.step == b.step).all()
