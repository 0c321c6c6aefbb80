"""scripts/reference_pages.py: the configuration and command-line references are the code's (the committed pages
are what the script writes); the first names every preset, key, flag and field of the labelling policy, and its
example runs; the second every command."""

import dataclasses
import subprocess
import sys

from tests.scriptfiles import load_script

from torch_gpioius.models.estimator import PRESETS
from torch_gpioius.models.labels import ObservationPolicy
from torch_gpioius.models.overrides import OVERRIDE_KEYS


def test_the_committed_page_is_what_the_code_writes():
    """Checked as a user runs it, in a fresh interpreter (kernels another test registers are not the package's)."""
    script = load_script("reference_pages")
    done = subprocess.run([sys.executable, str(script.__file__), "--check"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    page = script.PAGE.read_text()
    for name in PRESETS:
        assert f"| `{name}` |" in page
    for key in OVERRIDE_KEYS:
        assert f"| `{key}` |" in page
    for f in dataclasses.fields(ObservationPolicy):
        assert f"| `{f.name}` | " in page and ObservationPolicy.field_range(f.name) in page
    for flag in ("--kernel", "--lengthscale", "--noise", "--learn", "--voxel", "--estimator KEY=VALUE"):
        assert f"| `{flag}` |" in page
    cli = script.CLI_PAGE.read_text()
    for command in ("simulate", "simulate3d", "study", "fit", "replay", "import-bag", "view", "export"):
        assert f"## gpioius {command}\n" in cli


def test_the_pages_example_runs_as_written():
    script = load_script("reference_pages")
    text = script.PAGE.read_text()
    code = text.split("```python\n", 1)[1].split("```", 1)[0]
    scope: dict = {}
    exec(compile(code, "settings.md", "exec"), scope)           # noqa: S102 - the page's own example
    trace = scope["trace"]
    assert abs(trace.model.noise - 0.05) < 1e-12      # sigma^2, stored as a positive parameter
