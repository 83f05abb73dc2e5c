"""The tree's layers import one way: hersd (one run) <- sweeps (many runs); hersd <- analysis
(logs to figures). No module imports a layer above it, runs one (``python -m``, a subprocess,
``importlib``: any string naming its modules), and no import chain is circular."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LAYERS = {"hersd": 0, "sweeps": 1, "hydra_plugins": 1, "analysis": 1}  # analysis and sweeps never meet
MAY_IMPORT = {"hersd": {"hersd"}, "sweeps": {"hersd", "sweeps"}, "hydra_plugins": {"hersd", "sweeps"},
              "analysis": {"hersd", "analysis"}}


def project_imports() -> dict[str, set[str]]:
    """Module name -> the project modules it imports anywhere in its file (lazy imports included)."""
    graph: dict[str, set[str]] = {}
    for package in LAYERS:
        for path in (ROOT / package).rglob("*.py"):
            module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
            targets = set()
            for node in ast.walk(ast.parse(path.read_text())):
                names = [alias.name for alias in node.names] if isinstance(node, ast.Import) else \
                    [node.module] if isinstance(node, ast.ImportFrom) and node.module and node.level == 0 else []
                targets |= {name for name in names if name.split(".")[0] in LAYERS}
            graph[module] = targets
    return graph


def test_no_module_imports_a_layer_it_may_not():
    wrong = [f"{module} imports {target}" for module, targets in project_imports().items() for target in targets
             if target.split(".")[0] not in MAY_IMPORT[module.split(".")[0]]]
    assert not wrong, wrong


def named_layers(text: str) -> set[str]:
    """The layers a string names as modules: ``"analysis.report"``, ``"analysis.report:main"``, ``"-m analysis"``."""
    whole = re.fullmatch(r"(\w+)(\.\w+)*(:\w+)?", text)
    run = re.findall(r"-m\s+(\w+)", text)
    return ({whole.group(1)} if whole else set()) | set(run)


def test_no_module_runs_a_layer_it_may_not_import():
    """A module may not reach another layer around the imports, e.g. ``[sys.executable, "-m", "analysis.x"]``."""
    wrong = []
    for package in LAYERS:
        for path in (ROOT / package).rglob("*.py"):
            tree = ast.parse(path.read_text())
            docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                          if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                          and node.body and isinstance(node.body[0], ast.Expr)}
            for node in ast.walk(tree):
                if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
                    if named_layers(node.value) & set(LAYERS) - MAY_IMPORT[package] - {package}:
                        wrong.append(f"{path.relative_to(ROOT)}:{node.lineno} names {node.value!r}")
    assert not wrong, wrong


def test_no_import_circle():
    graph = project_imports()
    modules = set(graph)

    def resolve(target: str) -> str | None:  # "hersd.config.X" -> the module "hersd.config"
        while target and target not in modules:
            target = target.rpartition(".")[0]
        return target or None

    edges = {m: {resolve(t) for t in targets} - {None, m} for m, targets in graph.items()}
    state: dict[str, int] = {}

    def visit(module: str, path: list[str]) -> None:
        state[module] = 1
        for nxt in sorted(edges[module]):
            if state.get(nxt) == 1:
                pytest.fail("import circle: " + " -> ".join(path[path.index(nxt):] + [module, nxt]))
            if nxt not in state:
                visit(nxt, path + [module])
        state[module] = 2

    for module in sorted(edges):
        if module not in state:
            visit(module, [])


def test_the_core_imports_neither_optuna_nor_sqlalchemy():
    """hersd/ is one run: opening a study storage lives with its users (sweeps.search.storage for
    writing, analysis.studies read-only); the trial encoding they share (hersd/study.py) needs neither."""
    wrong = []
    for path in (ROOT / "hersd").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [alias.name for alias in node.names] if isinstance(node, ast.Import) else \
                [node.module] if isinstance(node, ast.ImportFrom) and node.module else []
            wrong += [f"{path.relative_to(ROOT)} imports {name}" for name in names
                      if name.split(".")[0] in ("optuna", "sqlalchemy")]
    assert not wrong, wrong


def test_light_modules_import_without_torch_or_mujoco():
    light = ["analysis", "analysis.report", "hersd.compose", "hersd.runstore", "hersd.runlog", "hersd.study",
             "hersd.config", "hersd.schedules", "hersd.envs.tasks", "hersd.resources", "sweeps.launch"]
    code = (f"import sys; import {', '.join(light)}; "
            "heavy = [m for m in ('torch', 'mujoco', 'gymnasium_robotics') if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_no_function_is_longer_than_60_lines_without_a_reason():
    """A longer function must say why on its ``def`` line (a comment containing 'long:')."""
    too_long = []
    for package in LAYERS:
        for path in (ROOT / package).rglob("*.py"):
            lines = path.read_text().splitlines()
            for node in ast.walk(ast.parse("\n".join(lines))):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    length = node.end_lineno - node.lineno + 1
                    if length > 60 and "long:" not in lines[node.lineno - 1]:
                        too_long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({length} lines)")
    assert not too_long, too_long


def test_the_architecture_doc_names_every_module_and_only_modules_that_exist():
    """docs/ARCHITECTURE.md matches the tree: every module of a layer is named there (as `name.py`),
    and every `*.py` it names exists (a path as given, a bare name somewhere in the layers)."""
    doc = (ROOT / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    named = set(re.findall(r"`([\w/]+\.py)`", doc))
    modules = [path for package in LAYERS for path in (ROOT / package).rglob("*.py") if path.name != "__init__.py"]
    unnamed = [str(path.relative_to(ROOT)) for path in modules if path.name not in {Path(n).name for n in named}]
    assert not unnamed, f"modules missing from docs/ARCHITECTURE.md: {unnamed}"
    names = {path.name for path in modules}
    ghosts = [n for n in named if not ((ROOT / n).exists() if "/" in n else n in names)]
    assert not ghosts, f"docs/ARCHITECTURE.md names modules that do not exist: {ghosts}"


def test_no_test_file_imports_another():
    """A test file's shared fixtures come from conftest.py (as fixtures, never imported) and its plain helpers from
    modules that are not test files (helpers.py, analysis_logs.py, servers.py): importing a test module runs its
    collection twice and ties two files' tests together."""
    test_modules = {path.stem for path in (ROOT / "tests").glob("test_*.py")} | {"conftest"}
    wrong = []
    for path in sorted((ROOT / "tests").glob("test_*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [alias.name for alias in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] + [alias.name for alias in node.names if node.level] \
                if isinstance(node, ast.ImportFrom) else []
            wrong += [f"tests/{path.name}:{node.lineno} imports {name}" for name in names
                      if name.split(".")[0] in test_modules or name.startswith("tests.test_")]
    assert not wrong, wrong
