"""The docs: the tutorials' code runs (in smoke form) and the site builds with ``mkdocs build --strict``."""

import os
import re
import shlex
import shutil
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


def test_mkdocs_build_strict_offline_with_rendered_math(tmp_path):
    """The site builds with --strict, fetches nothing from the network (no web fonts, no CDN: MathJax is copied in
    from the django-static-mathjax package), and its equations render in a browser."""
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings_handlers.python")
    pytest.importorskip("mathjax")
    site = tmp_path / "site"
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                          cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, done.stderr[-6000:]
    assert (site / "reference" / "models" / "index.html").exists()
    assert (site / "assets" / "mathjax" / "tex-mml-chtml.js").stat().st_size > 500_000
    assert any((site / "assets" / "mathjax" / "output" / "chtml" / "fonts" / "woff-v2").glob("*.woff"))
    for page in site.rglob("*.html"):
        html = page.read_text()
        assert "fonts.googleapis" not in html and "fonts.gstatic" not in html, page
        for src in re.findall(r'<script[^>]+src="([^"]+)"', html):
            assert not re.match(r"(https?:)?//", src), (page, src)      # every script is served by the site
    theory = (site / "theory" / "index.html").read_text()
    assert theory.count('class="arithmatex"') >= 6 and "mathjax/tex-mml-chtml.js" in theory
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    playwright = pytest.importorskip("playwright.sync_api") if chromium else None
    if chromium is None:
        pytest.skip("no Chromium to render the math in (CI installs Debian's)")
    import functools
    import http.server
    import threading

    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(site))
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    try:
        with playwright.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, args=["--no-sandbox"])
            page = browser.new_page()
            failed = []
            page.on("requestfailed", lambda r: failed.append(r.url))
            page.goto(f"http://127.0.0.1:{httpd.server_address[1]}/theory/")
            page.wait_for_selector("mjx-container", timeout=60_000)
            assert page.locator("mjx-container").count() >= 6
            assert not [u for u in failed if not u.startswith("http://127.0.0.1")], failed
            browser.close()
    finally:
        httpd.shutdown()


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


_CONSOLE = re.compile(r"^```console\n(.*?)^```", re.S | re.M)


def _quoted_commands() -> list[tuple[str, str, list[str]]]:
    """Every ``$ gpioius ...`` line in a ``console`` block of the README and docs, with the lines quoted after it."""
    found = []
    for md in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        for body in _CONSOLE.findall(md.read_text()):
            cmd, out = None, []
            for line in body.splitlines() + ["$ "]:
                if line.startswith("$ "):
                    if cmd:
                        found.append((str(md.relative_to(ROOT)), cmd, out))
                    cmd, out = line[2:].strip(), []
                else:
                    out.append(line)
    return found


QUOTED = _quoted_commands()


def test_the_docs_quote_commands_with_their_output():
    assert any(c.startswith("gpioius fit data/example_2d.gpioius") for _, c, _ in QUOTED)


@pytest.mark.parametrize("page, cmd, quoted", QUOTED, ids=[f"{p}: {c}" for p, c, _ in QUOTED])
def test_quoted_output_is_what_the_command_prints(page, cmd, quoted, capsys, monkeypatch):
    """Issue 33, item 11: docs/data-format.md printed K_t, similarity and MLL the command no longer printed."""
    from torch_gpioius.cli import main

    monkeypatch.chdir(ROOT)
    assert main(shlex.split(cmd)[1:]) == 0
    assert capsys.readouterr().out.rstrip("\n").splitlines() == quoted, f"{page} quotes other output for `{cmd}`"


def test_the_command_tables_writing_commands_each_name_their_own_folder():
    """The one-command-per-job table (docs/getting-started.md, once the README's) could not run in order when two
    commands wrote the same default folder."""
    table = [line for page in ("README.md", "docs/getting-started.md")
             for line in (ROOT / page).read_text().splitlines() if line.startswith("| ")]
    commands = [c for line in table for c in re.findall(r"`(gpioius (?:simulate3d|simulate|study) [^`]*)`", line)]
    assert len(commands) >= 5
    outs = []
    for c in commands:
        argv = shlex.split(c)
        assert "--out" in argv, f"command table: `{c}` writes the command's default folder; name one"
        outs.append(argv[argv.index("--out") + 1])
    assert len(set(outs)) == len(outs), f"command tables: two commands write one folder: {outs}"


def test_the_readme_says_what_a_second_run_into_its_own_folder_does():
    """Issue 51, item 23: the README said "No command replaces existing files ... unless given --force", while a
    second `fit --out` into its own folder replaces the earlier fit (as `--help` says)."""
    text = (ROOT / "README.md").read_text()
    assert "No command replaces existing files" not in text
    assert "into its own folder replaces that folder's results" in text


def test_the_architecture_page_lists_what_is_registered():
    """Issue 53: the docs' tables of kernels, worlds, touch models, evidence policies and sensors are the
    registries' own (``gpioius registered``); an entry added or renamed without the docs fails here."""
    from torch_gpioius.exploration.registry import registered_tables

    page = (Path(__file__).resolve().parents[1] / "docs" / "architecture.md").read_text()
    for kind, table in registered_tables(builtin_only=True).items():   # not the test files' own (test_extension)
        for row in table.splitlines()[2:]:
            assert row in page, f"docs/architecture.md lacks the {kind} row {row!r}"
