"""The docs: the tutorials' code runs (in smoke form) and the site builds with ``mkdocs build --strict``."""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = sorted((ROOT / "docs" / "tutorials").glob("*.md"))
_BLOCK = re.compile(r"^```(python|bash)\n(.*?)^```", re.S | re.M)
# commands that serve forever or need a robot are shown, not run
_NOT_RUN = ("gpioius view", "pip install")


def _script(md: Path) -> str:
    """One Python script of a page's blocks in order; its ``gpioius ...`` shell lines become subprocess calls."""
    parts = []
    for lang, body in _BLOCK.findall(md.read_text()):
        if lang == "python":
            parts.append(body)
            continue
        for line in body.splitlines():
            cmd = line.split("#")[0].strip()
            if cmd.startswith("gpioius") and not cmd.startswith(_NOT_RUN):
                argv = [sys.executable, "-m", "torch_gpioius.cli", *shlex.split(cmd)[1:]]
                parts.append(f"import subprocess as _sp\n_sp.run({argv!r}, check=True)\n")
    return "\n".join(parts)


@pytest.mark.parametrize("page", TUTORIALS, ids=[p.stem for p in TUTORIALS])
def test_tutorial_runs(page, tmp_path):
    if page.stem == "rosbag":
        pytest.importorskip("rosbags")
    script = tmp_path / f"{page.stem}.py"
    script.write_text(_script(page))
    env = {**os.environ, "CI": "1", "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    for var in ("UR5_HOST", "OPTOFORCE_PORT", "CAMERA_CLOUD"):     # never touch hardware from the test suite
        env.pop(var, None)
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, f"{page.name} failed:\n{done.stdout[-3000:]}\n{done.stderr[-5000:]}"


def _readme_block() -> str:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Use it"):]
    return _BLOCK.search(section).group(2)


def test_the_readme_python_block_runs_as_written(tmp_path):
    """The README's "Use it" block, extracted and run from a folder that holds the repository's data/ as the root
    does (it stopped at its first line with a NameError once)."""
    (tmp_path / "data").symlink_to(ROOT / "data")
    script = tmp_path / "readme.py"
    script.write_text(_readme_block())
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, f"README block failed:\n{done.stdout[-3000:]}\n{done.stderr[-5000:]}"


def test_every_long_readme_line_says_its_time_and_the_venv_is_explained():
    block = _readme_block()
    for line in block.splitlines():
        if "tg.explore(" in line or "paper_objects_3d()" in line:
            assert re.search(r"~\d+ s", line), f"no time given: {line}"
    text = (ROOT / "README.md").read_text()
    quick = text[text.index("## Quick start"):text.index("## Use it")]
    assert "source .venv/bin/activate" in quick and ".venv/bin/gpioius" in quick
    for page in TUTORIALS:
        body = page.read_text()
        first_cmd = body.find("gpioius ")
        assert "source .venv/bin/activate" in body[:max(first_cmd, 0)] or first_cmd < 0, page.name


def test_three_tutorials_exist():
    assert {p.stem for p in TUTORIALS} >= {"own-data", "rosbag", "real-robot"}


def test_mkdocs_build_strict(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings_handlers.python")
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                          cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, done.stderr[-6000:]
    assert (tmp_path / "site" / "reference" / "models" / "index.html").exists()


def test_the_own_data_tutorial_quotes_what_its_code_prints(tmp_path):
    """The explanation of the tutorial's result quotes the full-size output; it must be what the code prints."""
    page = ROOT / "docs" / "tutorials" / "own-data.md"
    text = page.read_text()
    quoted = re.search(r"```text\n(.*?)```", text, re.S).group(1).strip().splitlines()
    blocks = [b for lang, b in _BLOCK.findall(text) if lang == "python"][:2]
    script = tmp_path / "own.py"
    script.write_text("\n".join(blocks))
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    env.update(PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1", MPLBACKEND="Agg")
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().splitlines() == quoted
