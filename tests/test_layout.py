"""The package layout: stages import only downward, no import cycle, modules short enough."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _checker():
    spec = importlib.util.spec_from_file_location("check_layers", ROOT / "tools/check_layers.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_stages_import_downward_and_modules_stay_short():
    assert list(_checker().offences(ROOT)) == []


def test_no_two_modules_import_each_other():
    checker = _checker()
    assert checker.import_cycles(ROOT) == []


def test_the_cycle_check_finds_a_loop(tmp_path):
    package = tmp_path / "rimcl"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("def f():\n    from rimcl.b import g\n")
    (package / "b.py").write_text("from rimcl import a\n")
    assert _checker().import_cycles(tmp_path) == [["rimcl.a", "rimcl.b", "rimcl.a"]]
