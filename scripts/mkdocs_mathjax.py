"""MkDocs hook: copy MathJax 3 into the built site, so the docs render math offline.

The script and its fonts come from the ``django-static-mathjax`` package (a PyPI copy of MathJax 3's ``es5``
build, installed by the ``docs`` extra); nothing is fetched from a CDN when the site is built or viewed. The
component loads its fonts and the TeX extensions it autoloads (``\\boldsymbol``, ...) relative to its own location,
so the ``output/chtml/fonts`` and ``input/tex/extensions`` trees are copied beside it.
"""

from __future__ import annotations

import shutil
from pathlib import Path


def _source() -> Path:
    try:
        import mathjax  # the django-static-mathjax package
    except ImportError as exc:   # pragma: no cover - the docs extra is missing
        raise ImportError("building the docs needs MathJax: pip install -e '.[docs]' (django-static-mathjax)") from exc
    root = Path(mathjax.__file__).resolve().parent / "static" / "mathjax" / "es5"
    if not (root / "tex-mml-chtml.js").is_file():   # pragma: no cover - an unexpected package layout
        raise FileNotFoundError(f"{root}: MathJax's tex-mml-chtml.js is not where django-static-mathjax puts it")
    return root


def on_post_build(config, **kwargs) -> None:
    src = _source()
    dst = Path(config["site_dir"]) / "assets" / "mathjax"
    dst.mkdir(parents=True, exist_ok=True)
    shutil.copy2(src / "tex-mml-chtml.js", dst / "tex-mml-chtml.js")
    for tree in (("output", "chtml", "fonts", "woff-v2"), ("input", "tex", "extensions")):
        shutil.copytree(src.joinpath(*tree), dst.joinpath(*tree), dirs_exist_ok=True)
