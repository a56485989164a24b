"""Import layout rules of the developer guide, checked on the source.

Imports sit at the top of modules (a cycle is broken by moving the shared name, not by importing
inside a function). The exception is ``app/commands/*``: ``navdeck`` imports every command module
to build its parser, so a command imports its heavy modules inside its ``run`` function and
``navdeck --help`` never loads the server or the navigation stack."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Every product module (the server, the algorithms, the drivers, the map formats) except the commands.
PRODUCT_MODULES = sorted(
    str(path.relative_to(ROOT))
    for package in ("app", "nav", "robot", "maps")
    for path in (ROOT / package).rglob("*.py")
    if "commands" not in path.relative_to(ROOT).parts
)
TOP_IMPORTS_ONLY = [
    *PRODUCT_MODULES,
    "bench/bags.py",
    "bench/contact.py",
    "bench/editor.py",
    "bench/explore.py",
    "bench/peers.py",
    "bench/loc_criterion.py",
    "tests/test_app_session.py",
    "tests/test_localization_criterion.py",
    "tests/test_map_edit.py",
    "tests/test_patrol.py",
    "tests/test_places_api.py",
    "tests/test_unknown_space.py",
    "tests/test_zones_api.py",
    "tests/test_zone_masks.py",
    "tests/test_zones_nav.py",
]


def imports_inside_functions(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            found += [
                f"{path.name}:{inner.lineno} in {node.name}(): {ast.unparse(inner)}"
                for inner in ast.walk(node)
                if isinstance(inner, ast.Import | ast.ImportFrom)
            ]
    return found


@pytest.mark.parametrize("rel", TOP_IMPORTS_ONLY)
def test_module_imports_only_at_top(rel: str) -> None:
    assert imports_inside_functions(ROOT / rel) == []


def test_every_product_package_is_scanned() -> None:
    expected = {"app/runtime.py", "nav/navigator.py", "robot/sim/world.py", "maps/mapio.py"}
    assert expected <= set(PRODUCT_MODULES)
    assert not any(rel.startswith("app/commands/") for rel in PRODUCT_MODULES)


def test_scanner_sees_an_import_inside_a_function(tmp_path: Path) -> None:
    src = tmp_path / "m.py"
    src.write_text("import os\n\n\ndef f():\n    from math import pi\n    return pi\n")
    assert imports_inside_functions(src) == ["m.py:5 in f(): from math import pi"]


HEAVY = ("app.main", "app.runtime", "app.features", "app.session", "fastapi", "nav.navigator", "scipy")


def test_cli_parser_does_not_load_the_server_or_the_navigation_stack() -> None:
    """What ``navdeck --help`` imports: the parser and every command module, nothing heavy."""
    code = (
        "import sys; from app.cli import build_parser; build_parser(); "
        f"print(sorted(m for m in sys.modules if m.startswith({HEAVY!r})))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
