"""hersd/contract/plugins.py: a class found by its import path, and one line for each way it is not found."""

from __future__ import annotations

import pytest

from hersd.contract.errors import ConfigError
from hersd.contract.plugins import class_at

MODULES = {"__init__.py": "", "steps.py": "class Step:\n    pass\n", "broken.py": "x = (\n",
           "raising.py": "import math\nraise RuntimeError('no settings file')\n",
           "valueerror.py": "import json\n\nSETTINGS = json.loads('{')\n",
           "needs.py": "import no_such_dependency_plugins\n", "script.py": "import sys\n\nsys.exit(3)\n"}


@pytest.fixture
def user_pkg(tmp_path, monkeypatch):
    """A package ``user_pkg_plugins`` of one's own on sys.path: a good module, a broken one, one that raises."""
    folder = tmp_path / "user_pkg_plugins"
    folder.mkdir()
    for name, text in MODULES.items():
        (folder / name).write_text(text)
    monkeypatch.syspath_prepend(str(tmp_path))
    return folder


def test_a_class_is_found_by_its_path(user_pkg):
    assert class_at("user_pkg_plugins.steps.Step", "schedule").__name__ == "Step"


@pytest.mark.parametrize("path, line", [
    ("user_pkg_plugins.broken.X", r"^schedule class user_pkg_plugins\.broken\.X: importing user_pkg_plugins\.broken "
                                  r"raised SyntaxError: '\(' was never closed \(broken\.py, line 1\); fix that module$"),
    ("user_pkg_plugins.raising.X", r"^schedule class user_pkg_plugins\.raising\.X: importing user_pkg_plugins\.raising "
                                   r"raised RuntimeError: no settings file at .*raising\.py:2; fix that module$"),
    ("user_pkg_plugins.valueerror.X", r"^schedule class user_pkg_plugins\.valueerror\.X: importing "
                                      r"user_pkg_plugins\.valueerror raised JSONDecodeError: .* at .*valueerror\.py:3; "
                                      r"fix that module$"),
    ("user_pkg_plugins.needs.X", r"raised ModuleNotFoundError: No module named 'no_such_dependency_plugins' at "
                                 r".*needs\.py:1; fix that module$"),
    ("user_pkg_plugins.script.X", r"^schedule class user_pkg_plugins\.script\.X: importing user_pkg_plugins\.script "
                                  r"raised SystemExit: 3 at .*script\.py:3; fix that module$"),
    ("user_pkg_plugins.steps", r"^schedule class user_pkg_plugins\.steps: user_pkg_plugins\.steps is a module; "
                               r"give <module>\.<Class>$"),
    ("user_pkg_plugins.steps.Nope", r"has no attribute 'Nope'\); is the class's name right\?$"),
    ("no_such_pkg_plugins.X", r"\(No module named 'no_such_pkg_plugins'\); is its module on PYTHONPATH\?$"),
])
def test_a_class_not_found_is_one_line_saying_why(user_pkg, path, line):
    """A module whose own code fails (a SyntaxError, a raise at import) was a traceback, not one line."""
    with pytest.raises(ConfigError, match=line) as caught:
        class_at(path, "schedule")
    assert "\n" not in str(caught.value)
