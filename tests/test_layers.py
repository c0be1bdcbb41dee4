"""The package's structure, read from the source: every room (a top-level module or a folder)
imports only rooms on the floors below it (FLOORS, the order docs/design.md draws), so the
physics never imports the renderer or the application; no module imports another module's
private names; a folder per concern."""

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


# The package's rooms (a top-level module or a folder), lowest first: a room imports only rooms
# on floors below its own (docs/design.md draws them). Rooms on one floor do not import each
# other.
FLOORS = (("errors", "geometry", "stages"),
          ("inputs",),
          ("runtime",),
          ("energies",),
          ("body",),
          ("state", "saved_state", "export"),
          ("model",),
          ("physics",),
          ("contact",),
          ("integrators",),
          ("stability",),
          ("stepping",),
          ("render",),
          ("simulation",),
          ("app",))
FLOOR = {room: k for k, rooms in enumerate(FLOORS, start=1) for room in rooms}   # as drawn


def room(module: str) -> str:
    """The room of a dotted ti_cloth module ("ti_cloth.contact.colliders.sdf" -> "contact")."""
    return module.split(".")[1]


def upward_imports(sources) -> list[str]:
    """Every import of a ti_cloth module by a room on the same floor or a lower one."""
    bad = []
    for path in sources:
        if path == PACKAGE / "__init__.py":
            continue   # the package's face: its lazy __getattr__ may name the app for its users
        here = path.relative_to(PACKAGE).parts[0].removesuffix(".py")
        for module, names in imports(path):
            if not module.startswith("ti_cloth."):
                targets = [f"ti_cloth.{name}" for name in names] if module == "ti_cloth" else []
            else:
                targets = [module]
            for target in targets:
                there = room(target)
                if there != here and FLOOR[there] >= FLOOR[here]:
                    bad.append(f"{path.relative_to(PACKAGE)} ({here}, floor {FLOOR[here]}) "
                               f"imports {target} ({there}, floor {FLOOR[there]})")
    return bad


def test_imports_point_down_the_floors():
    sources = sorted(PACKAGE.rglob("*.py"))
    rooms = {p.relative_to(PACKAGE).parts[0].removesuffix(".py") for p in sources}
    assert rooms - {"__init__"} == set(FLOOR), "every room has a floor, every floor a room"
    assert upward_imports(sources) == []


def test_the_package_init_imports_every_name_lazily():
    """`import ti_cloth` imports none of its modules (nor Taichi): every public name is in
    LAZY, each pointing at a module below the app and the renderer that holds it."""
    import ti_cloth

    top_level = ast.parse((PACKAGE / "__init__.py").read_text()).body
    assert not [node for node in top_level if isinstance(node, ast.ImportFrom)]
    assert set(ti_cloth.LAZY) == set(ti_cloth.__all__)
    for name, (module, attribute) in ti_cloth.LAZY.items():
        assert not module.startswith((".app", ".render")), name
        path = PACKAGE / (module.lstrip(".").replace(".", "/") + ".py")
        init = PACKAGE / module.lstrip(".").replace(".", "/") / "__init__.py"
        assert path.is_file() or init.is_file(), (name, module)


def test_no_module_imports_private_names_of_another():
    bad = [f"{path.relative_to(PACKAGE)}: {module}.{name}"
           for path in sorted(PACKAGE.rglob("*.py")) for module, names in imports(path)
           for name in names if name.startswith("_") and module.startswith("ti_cloth")]
    assert bad == []


def test_the_checker_sees_a_forbidden_import(tmp_path, monkeypatch):
    """The checks can fail: imports are read as written, and a room importing one on its own
    floor or above is reported."""
    fake = tmp_path / "ti_cloth"
    fake.mkdir()
    (fake / "forces.py").write_text("from .render.image import write_png\nfrom .validation import _x\n")
    monkeypatch.setitem(globals(), "PACKAGE", fake)
    found = imports(fake / "forces.py")
    assert found == [("ti_cloth.render.image", ["write_png"]), ("ti_cloth.validation", ["_x"])]
    (fake / "geometry.py").write_text("from .simulation import Simulation\n")
    (fake / "physics").mkdir()
    (fake / "physics" / "wind.py").write_text("from ..integrators import make_integrator\n"
                                              "from ..model import Model\n")
    bad = upward_imports([fake / "geometry.py", fake / "physics" / "wind.py"])
    assert [line.split(" imports ")[1] for line in bad] == [
        "ti_cloth.simulation (simulation, floor 14)", "ti_cloth.integrators (integrators, floor 10)"]


def test_the_app_modules_keep_their_old_names():
    """ti_cloth.study and the other modules that moved into ti_cloth.app (and the scene file
    reader, into ti_cloth.inputs) still resolve."""
    from ti_cloth import cli, runner, scene, scene_file, study
    from ti_cloth.app import cli as app_cli
    from ti_cloth.app import study as app_study

    assert study is app_study and cli is app_cli
    assert scene.load_scene is ti_cloth.load_scene and runner.run_scene is ti_cloth.run_scene
    assert scene_file.SceneError.__module__ == "ti_cloth.inputs.scene_file"


ROOT = PACKAGE.parent
SOURCES = [p for folder in ("ti_cloth", "tests", "benchmarks", "demos", "tools")
           for p in sorted((ROOT / folder).rglob("*.py"))]
TAICHI_INTERNALS = ("_primal", "compiled_kernels", "get_runtime", "ti.lang.", "taichi.lang", "ti._lib",
                    "current_cfg")


def private_reaches(source: str) -> list[str]:
    """`x._name` where `_name` is not defined in this source (self, cls and this module's
    own classes and functions may use their own private names)."""
    tree = ast.parse(source)
    own = {n.name for n in ast.walk(tree) if isinstance(n, (ast.ClassDef, ast.FunctionDef))}
    own |= {t.attr for n in ast.walk(tree) if isinstance(n, (ast.Assign, ast.AnnAssign))
            for t in (n.targets if isinstance(n, ast.Assign) else [n.target])
            if isinstance(t, ast.Attribute)}
    return [f"line {n.lineno}: {ast.unparse(n)}" for n in ast.walk(tree)
            if isinstance(n, ast.Attribute) and n.attr.startswith("_")
            and not n.attr.startswith("__") and n.attr not in own]


# the one reach into Taichi's internals, deliberate (docs/design.md: its front end memoised),
# and the test that compares it with Taichi's own
TAICHI_FRONT_END = {"ti_cloth/runtime/frontend.py": ["taichi.lang"],
                    "tests/test_frontend.py": ["taichi.lang"]}


def test_no_source_reaches_a_private_name_of_another_module():
    """In the package, the tests, the benchmarks, the demos and the tools; and none reads
    Taichi's internals (the runtime counts its own compilations: backend.compilations) but
    runtime/frontend.py, which memoises Taichi's front end, and its test."""
    bad = {str(p.relative_to(ROOT)): private_reaches(p.read_text()) for p in SOURCES}
    assert {k: v for k, v in bad.items() if v} == {}
    internals = {str(p.relative_to(ROOT)): [w for w in TAICHI_INTERNALS if w in p.read_text()]
                 for p in SOURCES if p.name != "test_layers.py"}
    assert {k: v for k, v in internals.items() if v} == TAICHI_FRONT_END


def test_the_private_reach_checker_can_fail():
    assert private_reaches("import m\nm._hidden()\n") == ["line 2: m._hidden"]
    assert private_reaches("class A:\n    def _f(self):\n        self._g = 1\n"
                           "    def h(self, other):\n        other._f(); other._g\n") == []


def test_the_package_keeps_a_folder_per_concern():
    """At most 12 modules at the top of ti_cloth; the rest in inputs/, energies/, body/,
    physics/, contact/, integrators/, runtime/, render/ and app/."""
    top = sorted(p.name for p in PACKAGE.glob("*.py"))
    folders = sorted(p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists())
    assert len(top) <= 12, top
    assert folders == ["app", "body", "contact", "energies", "inputs", "integrators", "physics",
                       "render", "runtime"]
