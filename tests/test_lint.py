"""ruff (pyflakes and pycodestyle, the rules and the 120-character lines of pyproject.toml) over the package, the
kinematics, the tests, the scripts, the benchmarks and the examples: part of the suite, so that an unused import, an
undefined name or an overlong line fails the test command as a broken test does."""

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ["torch_gpioius", "kinematics", "tests", "scripts", "benchmarks", "examples"]


def test_ruff_passes_on_the_project():
    ruff = shutil.which("ruff", path=str(Path(sys.executable).parent)) or shutil.which("ruff")
    assert ruff, "ruff is a test dependency (pip install -e '.[test]')"
    done = subprocess.run([ruff, "check", "--no-cache", *FOLDERS], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
