"""The tree's layers, by folder, import one way: hersd/contract (what the others share) <- hersd/engine (one run)
<- sweeps (many runs); hersd/contract <- analysis (logs to figures); sweeps and analysis never meet. Every import
counts: at module level, inside a function, under ``if TYPE_CHECKING:``, relative ones. No module imports a layer
it may not, or a module by its path from before the split (hersd/__init__.py's MOVED: those are for users), runs
one (``python -m``, a subprocess, ``runpy``, ``importlib``, ``exec``: any string, or ``+`` of strings, naming its
modules), and no import chain is circular."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from hersd import moved_to

ROOT = Path(__file__).resolve().parent.parent
FOLDERS = ("hersd", "conf", "sweeps", "hydra_plugins", "analysis", "scripts", "benchmarks")  # every layer's files
PACKAGES = ("hersd", "sweeps", "hydra_plugins", "analysis")  # the installed code: docs/ARCHITECTURE.md names it all
# Layer -> the layers it may import. "hersd" is the package's face (its version and the old paths' table);
# "conf" the YAML configs' package, hersd.conf.
MAY_IMPORT = {
    "hersd": set(),
    "conf": set(),
    "contract": {"hersd", "conf", "contract"},
    "engine": {"hersd", "conf", "contract", "engine"},
    "sweeps": {"hersd", "conf", "contract", "engine", "sweeps"},
    "hydra_plugins": {"hersd", "conf", "contract", "engine", "sweeps", "hydra_plugins"},
    "analysis": {"hersd", "conf", "contract", "analysis"},
    "scripts": {"hersd", "conf", "contract", "scripts"},  # an operator's chores on the logs
    "benchmarks": {"hersd", "conf", "contract", "engine", "sweeps", "analysis", "benchmarks"},
}
MAY_NAME = {**MAY_IMPORT, "hersd": {"contract", "engine"}}  # the face's table names the modules it imports by name
ENTRY_POINT_GROUPS = {"hersd.schedules", "hersd.learners"}  # names of entry point groups, not of modules
HEAVY = ("torch", "mujoco", "gymnasium", "gymnasium_robotics")


def layer(module: str) -> str | None:
    """The layer of a project module by its folder (``hersd.contract.config`` -> contract), None for any other name."""
    parts = module.split(".")
    if parts[0] == "hersd":
        return "hersd" if len(parts) == 1 else parts[1] if parts[1] in ("contract", "engine", "conf") else None
    return parts[0] if parts[0] in FOLDERS else None


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(("hersd",) + parts if parts[0] == "conf" else parts).removesuffix(".__init__")


def files(folders=FOLDERS) -> list[Path]:
    return sorted(path for folder in folders for path in (ROOT / folder).rglob("*.py"))


def imported(path: Path, node: ast.AST) -> list[str]:
    """The modules one import statement of ``path`` names (``from m import n``: m and m.n), relative ones made absolute."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if not isinstance(node, ast.ImportFrom):
        return []
    module = module_name(path)
    package = (module if path.name == "__init__.py" else module.rpartition(".")[0]).split(".")
    base = node.module if not node.level else ".".join(
        package[:len(package) - node.level + 1] + ([node.module] if node.module else []))
    return [base] + [f"{base}.{alias.name}" for alias in node.names]


def imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every import anywhere in the file: module level, functions, TYPE_CHECKING blocks."""
    return [(node.lineno, name) for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
            for name in imported(path, node)]


def project_imports() -> dict[str, set[str]]:
    """Module name -> the project modules it imports anywhere in its file."""
    return {module_name(path): {name for _, name in imports(path) if layer(name)} for path in files()}


def test_no_module_imports_a_layer_it_may_not_or_an_old_path():
    wrong = []
    for path in files():
        own = layer(module_name(path))
        for line, name in imports(path):
            where = f"{path.relative_to(ROOT)}:{line} imports {name}"
            if moved_to(name):
                wrong.append(f"{where}, a path from before the split: import {moved_to(name)}")
            elif layer(name) and layer(name) not in MAY_IMPORT[own]:
                wrong.append(where)
    assert not wrong, wrong


def named_modules(text: str) -> set[str]:
    """The modules a string names: ``"analysis.report"``, ``"analysis.report:main"``, ``"-m analysis"``,
    ``f"analysis.{name}"``'s ``"analysis."``, and code for ``exec``: ``"import analysis"``, ``"from analysis import x"``."""
    whole = re.fullmatch(r"(\w+(?:\.\w+)*)\.?(:\w+)?", text)
    return ({whole.group(1)} if whole else set()) | set(re.findall(r"(?:-m|\bimport|\bfrom)\s+([\w.]+)", text))


def joined(node: ast.AST) -> str | None:
    """The string a ``+`` of string constants spells (``"hersd." + "engine.train"``), else None."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        left, right = joined(node.left), joined(node.right)
        return None if left is None or right is None else left + right
    return None


SCRIPTS = {name: target.partition(":")[0] for name, target in  # console script -> its module
           tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["scripts"].items()}
RUNNING_MODULES = ("subprocess", "os", "runpy")
RUNNERS = {"run", "Popen", "call", "check_call", "check_output", "system", "popen", "run_path"}  # theirs, imported by name


def run_modules(call: ast.Call) -> set[str]:
    """The modules a call of subprocess, os or runpy (or of their functions imported by name) runs by a console
    script or a file's path: ``["hersd-report", folder]``, ``"python analysis/report.py"``, ``run_path("x/y.py")``."""
    func = call.func
    of_module = isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name) and func.value.id in RUNNING_MODULES
    if not (of_module or isinstance(func, ast.Name) and func.id in RUNNERS):
        return set()
    words = [word for node in ast.walk(call) if isinstance(node, ast.Constant) and isinstance(node.value, str)
             for word in node.value.split()]
    return {SCRIPTS[word] for word in words if word in SCRIPTS} | \
        {word.removeprefix("./").removesuffix(".py").replace("/", ".") for word in words if word.endswith(".py")}


def test_no_module_runs_a_layer_it_may_not_import():
    """A module may not reach another layer around the imports, e.g. ``[sys.executable, "-m", "analysis.x"]``,
    ``importlib.import_module(f"analysis.{x}")``, ``subprocess.run(["hersd-report", folder])``."""
    wrong = []
    for path in files():
        own = layer(module_name(path))
        tree = ast.parse(path.read_text(encoding="utf-8"))
        docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                      if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                      and node.body and isinstance(node.body[0], ast.Expr)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                names = {name: f"runs {name}" for name in run_modules(node)}
            elif (text := joined(node)) is not None and id(node) not in docstrings:
                names = {name: f"names {text!r}" for name in named_modules(text)}
            else:
                continue
            for name, what in names.items():
                target = layer(moved_to(name) or name)
                if name not in ENTRY_POINT_GROUPS and ((moved_to(name) and own != "hersd")
                                                       or target not in MAY_NAME[own] | {own, "hersd", None}):
                    wrong.append(f"{path.relative_to(ROOT)}:{node.lineno} {what}")
    assert not wrong, wrong


def test_no_import_circle():
    graph = project_imports()
    modules = set(graph)

    def resolve(target: str) -> str | None:  # "hersd.contract.config.X" -> the module "hersd.contract.config"
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


def test_the_contract_imports_neither_torch_nor_mujoco_nor_a_study_storage():
    """hersd/contract loads neither torch nor MuJoCo (analysis neither); no part of hersd imports Optuna or
    SQLAlchemy: opening a study storage lives with its users (sweeps.search.storage for writing,
    analysis.studies read-only); the trial encoding they share (hersd/contract/study.py) needs neither."""
    storage = ("optuna", "sqlalchemy")
    banned = {"hersd": storage, "conf": storage, "contract": HEAVY + storage, "engine": storage, "analysis": HEAVY}
    wrong = [f"{path.relative_to(ROOT)}:{line} imports {name}" for path in files(("hersd", "conf", "analysis"))
             for line, name in imports(path) if name.split(".")[0] in banned.get(layer(module_name(path)), ())]
    assert not wrong, wrong


def test_the_contract_analysis_and_the_sweep_planner_load_neither_torch_nor_mujoco():
    light = ["analysis", "sweeps.plan", "sweeps.launch", "sweeps.status"] + [
        module_name(path) for path in files(("hersd/contract", "analysis"))]
    code = (f"import sys; import {', '.join(light)}; "
            f"heavy = [m for m in {HEAVY!r} if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


# Entry point groups whose packages a layer loads by configuration (pyproject.toml), though it may not import them:
# group -> (the layer that loads it, the layer its packages lie in). docs/ARCHITECTURE.md names each.
LOADED_BY_CONFIGURATION = {"hersd.learner_modules": ("contract", "engine")}


def test_an_entry_point_reaches_a_layer_up_only_as_the_architecture_doc_says():
    """pyproject.toml's entry points are imports by configuration: a group naming modules of a layer that the
    layer loading the group may not import is listed above and in docs/ARCHITECTURE.md, nothing else."""
    declared = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["entry-points"]
    loaders = {group: {layer(module_name(path)) for path in files() if repr(group) in path.read_text(encoding="utf-8")
                       or f'"{group}"' in path.read_text(encoding="utf-8")} for group in declared}
    found = {}
    for group, points in declared.items():
        for loader in loaders[group]:
            for target in {layer(value.partition(":")[0]) for value in points.values()} - {None}:
                if target not in MAY_IMPORT[loader]:
                    found[group] = (loader, target)
    assert found == LOADED_BY_CONFIGURATION
    doc = (ROOT / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    assert all(f"`{group}`" in doc for group in found)


def defined_names(path: Path) -> set[str]:
    """The names a module defines at its top level itself (def, class, assignment), not those it imports."""
    names = set()
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names |= {name.id for target in targets for name in ast.walk(target) if isinstance(name, ast.Name)}
    return names


def test_every_name_is_imported_from_the_module_that_defines_it():
    """A fact is stated once, in the module that owns it, and asked of that module: ``from m import n`` names the
    module defining n (e.g. ConfigError from hersd.contract.errors, not through hersd.contract.config, which
    imports it). A package's ``__init__`` is its face: importing through it is allowed."""
    modules = {module_name(path): path for path in files()}
    wrong = []
    for path in files() + sorted((ROOT / "tests").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            source = modules.get(node.module) if isinstance(node, ast.ImportFrom) and not node.level else None
            if source is None or source.name == "__init__.py":
                continue
            defined = defined_names(source)
            wrong += [f"{path.relative_to(ROOT)}:{node.lineno} imports {alias.name} through {node.module}"
                      for alias in node.names if alias.name not in defined and f"{node.module}.{alias.name}" not in modules]
    assert not wrong, wrong


def test_no_function_is_longer_than_60_lines_without_a_reason():
    """A longer function must say why on its ``def`` line (a comment containing 'long:')."""
    too_long = []
    for path in files():
        lines = path.read_text().splitlines()
        for node in ast.walk(ast.parse("\n".join(lines))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > 60 and "long:" not in lines[node.lineno - 1]:
                    too_long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({length} lines)")
    assert not too_long, too_long


def test_no_file_in_sweeps_is_over_300_lines():
    """Many runs stay one planner and one job pool: a file of sweeps/ that grows past 300 lines is split by concern."""
    long = [f"{path.relative_to(ROOT)} ({count} lines)" for path in files(("sweeps",))
            if (count := len(path.read_text(encoding="utf-8").splitlines())) > 300]
    assert not long, long


def test_the_architecture_doc_names_every_module_and_only_modules_that_exist():
    """docs/ARCHITECTURE.md matches the tree: every module of the packages is named there (as `name.py`),
    and every `*.py` it names exists (a path as given, a bare name somewhere in the packages)."""
    doc = (ROOT / "docs" / "ARCHITECTURE.md").read_text(encoding="utf-8")
    named = set(re.findall(r"`([\w/]+\.py)`", doc))
    modules = [path for path in files(PACKAGES) if path.name != "__init__.py"]
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
