"""What the base install must hold: every third-party module the package imports at module
level, and every one the demos reach, is a base dependency of pyproject.toml; an optional
extra's module is imported only inside the function that needs it (lazily), so a base
install imports the whole package and runs every demo."""

import ast
import sys
from pathlib import Path

from helpers import ROOT, base_and_optional_modules, base_install


def third_party_imports(path: Path):
    """(module, at module level) of every import of a module outside the standard library and
    ti_cloth in `path`."""
    tree = ast.parse(path.read_text())
    top = {id(node) for node in tree.body}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        for name in names:
            root = name.split(".")[0]
            if root not in sys.stdlib_module_names and root not in ("ti_cloth", "__future__"):
                yield root, id(node) in top


def test_the_base_install_holds_what_the_package_and_the_demos_import():
    base, optional = base_and_optional_modules()
    assert {"scipy", "igl"} <= base            # garments and mesh colliders: the showcase
    unknown, eager, demo_needs = set(), set(), set()
    for path in sorted((ROOT / "ti_cloth").rglob("*.py")):
        for module, at_top in third_party_imports(path):
            if module not in base | optional:
                unknown.add(f"{path.relative_to(ROOT)}: {module}")
            elif module in optional and at_top:
                eager.add(f"{path.relative_to(ROOT)}: {module}")
    for path in sorted((ROOT / "demos").rglob("*.py")):
        demo_needs |= {m for m, _ in third_party_imports(path) if m not in base}
    assert not unknown, f"imports of no declared dependency: {sorted(unknown)}"
    assert not eager, f"optional extras imported at module level: {sorted(eager)}"
    assert not demo_needs, f"demos import what the base install lacks: {sorted(demo_needs)}"


def test_the_base_install_stand_in_makes_every_extra_unimportable():
    """test_demos runs the demos inside base_install(): an extra's module, imported before
    or not, cannot be imported there, and is back after."""
    import importlib

    import pxr                                  # in the [test] extra: present here
    with base_install() as optional:
        assert {"pxr", "matplotlib", "distributed"} <= optional
        for name in optional:
            try:
                importlib.import_module(name)
            except ImportError:
                continue
            raise AssertionError(f"{name} imported inside base_install()")
    assert importlib.import_module("pxr") is pxr
