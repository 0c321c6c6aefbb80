"""The package's shape (docs/architecture.md): every module imports only layers below its own, at module level and
inside functions alike, so no import circle can form; no module imports another module's private name; the
exploration loop stays a short pipeline."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "torch_gpioius"

#: The layers, lowest first (docs/architecture.md). A module may import its own layer and those before it.
LAYERS = [
    {"_version", "core"},
    {"geometry"},
    {"kernels"}, {"inference"}, {"models"},
    {"sensors"}, {"exploration"}, {"sim"}, {"baselines"}, {"io"}, {"testing"}, {"session", "fitting"},
    {"studies"},
    {"viewer"},
    {"cli"},
    {"(root)"},
]
#: The root holds the package's face, its version and the applications (one module per user-facing job); the
#: foundation (core), geometry and every other layer live in their own folders.
ROOT_MODULES = {"__init__", "_version", "session", "fitting", "baselines", "viewer", "cli"}
LAYER = {name: i for i, layer in enumerate(LAYERS) for name in layer}
#: Imports inside a function that go up on purpose: a deprecated name forwarded to its new home (``__getattr__``)
#: and the registry loading a built-in world's module by name (importlib, not an import statement).
SHIMS = {"__getattr__"}


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE)
        top = "(root)" if rel.name == "__init__.py" and len(rel.parts) == 1 else rel.parts[0].removesuffix(".py")
        yield path, rel, top


def _imports(path: Path, rel: Path):
    """``(target top-level name, imported names, line, enclosing function or None)`` of every relative import."""
    tree = ast.parse(path.read_text())
    parents = {}
    for node in ast.walk(tree):
        for child in ast.iter_child_nodes(node):
            parents[child] = node
    pkg = list(rel.parts[:-1])
    for node in ast.walk(tree):
        if not (isinstance(node, ast.ImportFrom) and node.level > 0):
            continue
        base = pkg[:len(pkg) - (node.level - 1)] if node.level > 1 else pkg
        target = base + (node.module.split(".") if node.module else [])
        top = target[0] if target else "(root)"
        if not node.module and not base:              # "from . import x" in the root package
            top = "(root)"
        func, up = None, parents.get(node)
        while up is not None:
            if isinstance(up, (ast.FunctionDef, ast.AsyncFunctionDef)):
                func = up.name
                break
            up = parents.get(up)
        yield top, [a.name for a in node.names], node.lineno, func


def test_the_root_holds_only_the_face_and_the_applications():
    """The root's modules were once nineteen, foundation, geometry and applications side by side; each layer below the
    applications now has its folder (docs/architecture.md)."""
    found = {p.stem for p in PACKAGE.glob("*.py")}
    assert found == ROOT_MODULES, f"modules at the root beside the applications: {sorted(found - ROOT_MODULES)}"


def test_every_module_imports_only_lower_layers():
    """Up-imports are how import circles form; one inside a function only hides the circle."""
    bad = []
    for path, rel, top in _modules():
        assert top in LAYER, f"{rel}: not in any layer; add it to LAYERS and docs/architecture.md"
        for target, names, line, func in _imports(path, rel):
            if target == "(root)" and names == ["__version__"]:
                target = "_version"
            if target not in LAYER:
                continue
            if LAYER[target] > LAYER[top] and func not in SHIMS:
                bad.append(f"{rel}:{line} ({top}) imports {target}" + (f" inside {func}()" if func else ""))
    assert not bad, "imports that go up a layer:\n" + "\n".join(bad)


def test_no_module_imports_another_modules_private_name():
    bad = [f"{rel}:{line} imports {n}" for path, rel, _ in _modules()
           for _, names, line, _ in _imports(path, rel) for n in names if n.startswith("_") and not n.startswith("__")
           and n not in ("_version",)]
    assert not bad, "\n".join(bad)


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs os.fork (POSIX)")
def test_importing_each_module_alone_works():
    """Every module imports on its own, first of the package, in a fresh process (a circle shows up as an
    ImportError): a forked child of an interpreter that holds only third-party modules."""
    import subprocess
    import sys

    names = []
    for path, rel, _ in _modules():
        parts = list(rel.with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names.append(".".join(["torch_gpioius", *parts]))
    # One fresh interpreter imports the heavy third-party roots once (torch alone takes ~2 s) and forks a child per
    # module, which imports that module with no torch_gpioius module loaded yet: a circle inside the package still
    # fails there, as in a fresh interpreter, at ~0.3 s per module instead of ~3 s.
    script = f"""
import json, os, sys, traceback
import numpy, torch, gpytorch, trimesh   # no torch_gpioius module: the parent never imports the package
assert not any(m.split('.')[0] == 'torch_gpioius' for m in sys.modules)
failed = []
for name in {names!r}:
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(r)
        try:
            __import__(name)
            code, msg = 0, b""
        except BaseException:
            code, msg = 1, traceback.format_exc().strip().splitlines()[-1].encode()
        os.write(w, msg)
        os._exit(code)
    os.close(w)
    with os.fdopen(r, "rb") as f:
        msg = f.read().decode()
    _, status = os.waitpid(pid, 0)
    if status != 0:
        failed.append(name + ": " + (msg or "exit status " + str(status)))
print(json.dumps(failed))
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600, cwd=PACKAGE.parent)
    assert r.returncode == 0, r.stderr[-2000:]
    failed = __import__("json").loads(r.stdout.strip().splitlines()[-1])
    assert not failed, "\n".join(failed)


@pytest.mark.parametrize("name", ["run", "step", "begin"])
def test_the_loop_is_short(name):
    """The loop only calls its stages and hooks (dm_control's Environment.step is 29 lines)."""
    tree = ast.parse((PACKAGE / "exploration" / "loop.py").read_text())
    fn = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == name)
    assert fn.end_lineno - fn.lineno + 1 <= 80


@pytest.mark.parametrize("module, name", [("io/rosbag.py", "import_bag"), ("studies/study.py", "run_sweep")])
def test_the_long_entry_points_are_short_steps_over_checked_settings(module, name):
    """Issue 35, item 22: import_bag was one 270-line function and run_sweep 121 lines; each now checks its
    arguments into a settings object (``.checked(...)``) and calls a few steps: the body (docstring aside) stays
    short, and so does every step it calls."""
    tree = ast.parse((PACKAGE / module).read_text())
    functions = {n.name: n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    fn = functions[name]
    body = fn.body[1:] if isinstance(fn.body[0], ast.Expr) else fn.body
    assert body[-1].end_lineno - body[0].lineno + 1 <= 25
    calls = {c.func.attr if isinstance(c.func, ast.Attribute) else c.func.id for n in body for c in ast.walk(n)
             if isinstance(c, ast.Call) and isinstance(c.func, (ast.Attribute, ast.Name))}
    assert "checked" in calls
    steps = [functions[c] for c in calls if c in functions and isinstance(functions[c], ast.FunctionDef)]
    for step in steps:
        assert step.end_lineno - step.lineno + 1 <= 100, step.name


def _module_graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (module level and inside functions; a package's ``__init__`` and
    the deprecated-name forwards in ``__getattr__`` left out), by dotted path under the package."""
    graph: dict[str, set[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE)
        if rel.name == "__init__.py":
            continue
        me = ".".join(rel.with_suffix("").parts)
        out = graph.setdefault(me, set())
        tree = ast.parse(path.read_text())
        shims = {n for f in ast.walk(tree) if isinstance(f, ast.FunctionDef) and f.name in SHIMS for n in ast.walk(f)}
        pkg = list(rel.parts[:-1])
        for node in ast.walk(tree):
            if not (isinstance(node, ast.ImportFrom) and node.level > 0) or node in shims:
                continue
            base = pkg[:len(pkg) - (node.level - 1)] if node.level > 1 else pkg
            target = base + (node.module.split(".") if node.module else [])
            for name in [a.name for a in node.names]:
                for parts in (target + [name], target):          # a submodule by name, else the module itself
                    f = PACKAGE.joinpath(*parts)
                    if f.with_suffix(".py").is_file() if parts else False:
                        out.add(".".join(parts))
                        break
    return graph


def test_no_two_modules_import_each_other():
    """io/export.py and the fitting module (then io/offline.py) once imported each other, and sensors/pointcloud.py
    reached up into io/importers.py, which imports it; a circle between modules, even through function-level
    imports."""
    graph = _module_graph()
    assert "io.export" in graph["fitting"]
    circles, state = [], {}

    def visit(m, stack):
        state[m] = 1
        for n in sorted(graph.get(m, ())):
            if state.get(n) == 1:
                circles.append(" -> ".join(stack[stack.index(n):] + [n]))
            elif n not in state:
                visit(n, stack + [n])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert not circles, "modules that import each other:\n" + "\n".join(circles)


def test_the_renamed_settings_still_import_with_a_warning():
    """"settings" names the estimator's settings alone: the other three were renamed (exact arithmetic, a study's
    plan, a patch's thinning); their old names still import, for one release, with a DeprecationWarning."""
    import importlib
    import sys

    import torch_gpioius.core.exact as exact
    import torch_gpioius.exploration as exploration
    from torch_gpioius.exploration.patches import PatchThinning
    from torch_gpioius.studies import study as sweep, study_plan

    sys.modules.pop("torch_gpioius.settings", None)
    with pytest.warns(DeprecationWarning, match="torch_gpioius.core.exact"):
        old = importlib.import_module("torch_gpioius.settings")
    assert old.exact_arithmetic is exact.exact_arithmetic
    for module, name, new in ((exploration, "PatchSettings", PatchThinning), (sweep, "SweepSettings", sweep.StudyPlan),
                              (study_plan, "SweepSettings", sweep.StudyPlan)):
        with pytest.warns(DeprecationWarning, match=new.__name__):
            assert getattr(module, name) is new


def test_one_public_explore():
    """torch_gpioius.explore is the one explore; the loop's own (which took the same settings without the log) is
    gone from torch_gpioius.exploration, and its old names give the one with a DeprecationWarning."""
    import torch_gpioius as tg
    from torch_gpioius.exploration import loop

    assert "explore" not in tg.exploration.__all__ and "explore" not in loop.__all__
    for module in (tg.exploration, loop):
        with pytest.warns(DeprecationWarning, match="is torch_gpioius.explore now"):
            assert module.explore is tg.explore


#: "About ten": a public function with more parameters than this says why in its docstring (or its class's).
MANY_PARAMETERS = 10


def test_no_public_function_takes_many_parameters_without_saying_why():
    """Signatures stay readable: what travels together is one object (the estimator's settings, a study's plan);
    where a function still takes many separate choices, its docstring says why ("Why this many parameters")."""
    bad = []
    for path, rel, _ in _modules():
        tree = ast.parse(path.read_text())
        for cls in [None, *[n for n in ast.walk(tree) if isinstance(n, ast.ClassDef)]]:
            body = tree.body if cls is None else cls.body
            if cls is not None and cls.name.startswith("_"):
                continue
            for node in body:
                if not isinstance(node, ast.FunctionDef) or (node.name.startswith("_") and node.name != "__init__"):
                    continue
                args = node.args
                names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs if a.arg not in ("self", "cls")]
                if len(names) <= MANY_PARAMETERS:
                    continue
                docs = (ast.get_docstring(node) or "") + (ast.get_docstring(cls) or "" if cls is not None else "")
                if "Why this many parameters" not in " ".join(docs.split()):
                    where = f"{cls.name}." if cls is not None else ""
                    bad.append(f"{rel}:{node.lineno} {where}{node.name}: {len(names)} parameters")
    assert not bad, "public functions with many parameters and no reason given:\n" + "\n".join(bad)


@pytest.mark.parametrize("old, new", [("study2d", "simulate"), ("study3d", "simulate3d"), ("sweep", "study"),
                                      ("sweep_settings", "study_plan"), ("sweep_runs", "study_runs"),
                                      ("sweep_aggregate", "study_aggregate"), ("sweep_figures", "study_figures")])
def test_the_studies_modules_are_named_for_their_commands_and_the_old_names_still_import(old, new):
    """gpioius simulate runs studies.simulate, simulate3d studies.simulate3d, study studies.study (and its plan, runs,
    tables and figures); the old module names import for one release, with a warning, and give the same objects."""
    import importlib
    import sys

    moved = importlib.import_module(f"torch_gpioius.studies.{new}")
    sys.modules.pop(f"torch_gpioius.studies.{old}", None)
    with pytest.warns(DeprecationWarning, match=f"studies.{old} is torch_gpioius.studies.{new} now"):
        shim = importlib.import_module(f"torch_gpioius.studies.{old}")
    name = next(n for n in dir(moved) if not n.startswith("_") and callable(getattr(moved, n)))
    assert getattr(shim, name) is getattr(moved, name)


def test_fitting_has_its_own_room_and_its_old_names_still_work():
    """What gpioius fit and replay do lives in torch_gpioius.fitting, apart from the file formats of io/; 0.1's
    tg.offline is that module, and torch_gpioius.io.offline imports for one release with a warning."""
    import importlib
    import sys

    import torch_gpioius as tg
    from torch_gpioius import fitting

    assert tg.offline is fitting and tg.fitting is fitting and "offline" not in tg.io.__all__
    sys.modules.pop("torch_gpioius.io.offline", None)
    with pytest.warns(DeprecationWarning, match="torch_gpioius.io.offline is torch_gpioius.fitting now"):
        old = importlib.import_module("torch_gpioius.io.offline")
    assert old.fit_dataset is fitting.fit_dataset and old.replay_log is fitting.replay_log
