"""The package's layers, read from the source: the physics never imports the renderer or the
application (ti_cloth.app), the renderer never imports the application, and no module imports
another module's private names."""

import ast
from pathlib import Path

import ti_cloth

PACKAGE = Path(ti_cloth.__file__).parent


def imports(path: Path) -> list[tuple[str, list[str]]]:
    """(absolute module, imported names) of every import in a ti_cloth source file."""
    module = ".".join(("ti_cloth",) + path.relative_to(PACKAGE).with_suffix("").parts)
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found += [(alias.name, []) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parent + ([node.module] if node.module else []))
            found.append((base, [alias.name for alias in node.names]))
    return found


def layer(path: Path) -> str:
    parts = path.relative_to(PACKAGE).parts
    return parts[0] if parts[0] in ("app", "render") else "physics"


def test_imports_point_down_the_layers():
    forbidden = {"physics": ("ti_cloth.app", "ti_cloth.render"), "render": ("ti_cloth.app",),
                 "app": ()}
    sources = sorted(PACKAGE.rglob("*.py"))
    assert len(sources) > 30 and {layer(p) for p in sources} == set(forbidden)
    bad = []
    for path in sources:
        for module, names in imports(path):
            targets = [module] + [f"{module}.{name}" for name in names]
            if path.name == "__init__.py" and path.parent == PACKAGE:
                continue   # the package's lazy __getattr__ may name the app for its users
            if any(t == f or t.startswith(f + ".") for t in targets for f in forbidden[layer(path)]):
                bad.append(f"{path.relative_to(PACKAGE)} imports {module} {names}")
    assert bad == []


def test_the_package_init_imports_the_app_only_lazily():
    top_level = ast.parse((PACKAGE / "__init__.py").read_text()).body
    eager = [node for node in top_level if isinstance(node, ast.ImportFrom)]
    assert eager and not any((node.module or "").startswith(("app", "render")) for node in eager)


def test_no_module_imports_private_names_of_another():
    bad = [f"{path.relative_to(PACKAGE)}: {module}.{name}"
           for path in sorted(PACKAGE.rglob("*.py")) for module, names in imports(path)
           for name in names if name.startswith("_") and module.startswith("ti_cloth")]
    assert bad == []


def test_the_checker_sees_a_forbidden_import(tmp_path, monkeypatch):
    """The layer test can fail: a physics module importing the renderer is reported."""
    fake = tmp_path / "ti_cloth"
    fake.mkdir()
    (fake / "forces.py").write_text("from .render.image import write_png\nfrom ._validate import _x\n")
    monkeypatch.setitem(globals(), "PACKAGE", fake)
    found = imports(fake / "forces.py")
    assert found == [("ti_cloth.render.image", ["write_png"]), ("ti_cloth._validate", ["_x"])]
    assert layer(fake / "forces.py") == "physics"


def test_the_app_modules_keep_their_old_names():
    """ti_cloth.study and the other modules that moved into ti_cloth.app still resolve."""
    from ti_cloth import cli, runner, scene, scene_file, study
    from ti_cloth.app import cli as app_cli, study as app_study

    assert study is app_study and cli is app_cli
    assert scene.load_scene is ti_cloth.load_scene and runner.run_scene is ti_cloth.run_scene
    assert scene_file.SceneError.__module__ == "ti_cloth.app.scene_file"
