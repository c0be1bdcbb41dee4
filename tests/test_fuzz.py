"""Property-based hostile input (Hypothesis): a generated scene file either runs a frame or
is refused with the project's error naming a key; generated API arguments construct or raise
ValueError naming the argument. Never another exception, never a non-finite position, never
long (each example has a deadline). The hand-picked cases are in test_hostile_input.py."""

import json
import re

import numpy as np
import pytest
from helpers import use
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import ti_cloth as tc
from ti_cloth.app.scene import load_scene
from ti_cloth.app.view import viewer_for
from ti_cloth.inputs.scene_file import SceneError
from ti_cloth.runtime import backend

BASE = {
    "scene": {"name": "fuzz"},
    "simulation": {"integrator": "symplectic_euler", "fps": 30, "duration": 1.0, "resolution": 1,
                   "strain_limit": {"max_strain": 0.1}},
    "forces": {"gravity": [0, -9.81, 0], "drag": 0.1, "wind": {"velocity": [1, 0, 0], "seed": 3}},
    "bodies": [{"type": "grid", "rows": 6, "cols": 6, "size": [1, 1], "pinned": ["top"],
                "material": {"density": 0.2, "stretch": {"k": 500, "kd": 0.5}},
                "handles": [{"particles": ["top_left"],
                             "path": {"type": "oscillation", "amplitude": [0, 0.1, 0],
                                      "frequency": 1}}]}],
    "colliders": [{"type": "sphere", "centre": [0, -1, 0], "radius": 0.3}],
    "camera": {"fov": 40, "direction": [0.5, 0.4, 1]},
    "output": {"width": 64, "height": 48, "supersample": 1, "style": {"wireframe": 1}},
}


def paths(table, prefix=()):
    """Every key path of a nested scene: ("bodies", 0, "material", "density"), ..."""
    items = table.items() if isinstance(table, dict) else enumerate(table)
    for key, value in items:
        yield prefix + (key,)
        if isinstance(value, (dict, list)) and (isinstance(value, dict) or
                                                all(isinstance(v, dict) for v in value)):
            yield from paths(value, prefix + (key,))


PATHS = [p for p in paths(BASE) if isinstance(p[-1], str)]
KEY_NAMES = sorted({p[-1] for p in PATHS} | {"integrator", "name", "Camera", "vertices"})

scalars = st.one_of(
    st.integers(min_value=-2**80, max_value=2**80),
    st.sampled_from([0, 1, -1, 2**31, 2**63 - 1, 10**20]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-320, 1e-300, 1e300, float("nan"), float("inf"), -1e9]),
    st.booleans(),
    st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=12),
    st.sampled_from(["auto", "top", "", "..", "pbd", "xz"]),
)
values = st.recursive(scalars, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(["k", "kd", "name", "x"]), inner,
                                                 max_size=3)), max_leaves=8)


def toml(value) -> str:
    """A TOML literal (inline tables, arrays; JSON string escapes are TOML's)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if value != value else "inf" if value == np.inf else "-inf" if value == -np.inf else repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(toml(v) for v in value) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {toml(v)}" for k, v in value.items()) + "}"


def document(scene: dict) -> str:
    """The scene as TOML: one [table] or [[array]] per top-level key, inline below."""
    lines = []
    for key, value in scene.items():
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for item in value:
                lines += [f"[[{key}]]"] + [f"{k} = {toml(v)}" for k, v in item.items()]
        elif isinstance(value, dict):
            lines += [f"[{key}]"] + [f"{k} = {toml(v)}" for k, v in value.items()]
        else:
            lines.insert(0, f"{key} = {toml(value)}")
    return "\n".join(lines) + "\n"


class Scale(float):
    """A change that multiplies the numbers already at a path (a knob turned, most often
    to a value the scene still accepts) instead of replacing them."""


def scaled(value, factor: float):
    if isinstance(value, bool) or not isinstance(value, (int, float, list)):
        return value
    if isinstance(value, list):
        return [scaled(v, factor) for v in value]
    return type(value)(value * factor) if isinstance(value, float) else round(value * factor)


def mutated(changes, base=BASE) -> tuple[dict, list[str]]:
    scene = json.loads(json.dumps(base))
    touched = []
    for path, value, new_key in changes:
        owner = scene
        for key in path[:-1]:
            owner = reach(owner, key)
        key = path[-1] if new_key is None else new_key
        if isinstance(value, Scale) and isinstance(owner, dict) and key in owner:
            owner[key] = scaled(owner[key], value)
        elif isinstance(owner, dict) and not isinstance(value, Scale):
            owner[key] = value
        else:
            continue
        touched.append(str(key))
    return scene, touched


def reach(owner, key):
    """owner[key], or None where an earlier change replaced the path's parent."""
    if isinstance(owner, dict):
        return owner.get(key)
    if isinstance(owner, list) and isinstance(key, int) and key < len(owner):
        return owner[key]
    return None


factors = st.sampled_from([0.0, -1.0, 0.01, 0.3, 0.5, 2.0, 3.0, 10.0, 1e3]).map(Scale)
def change_lists(key_paths, *more_values):
    """One to three changes of the keys at `key_paths`: a value, a factor, or (a new key)
    the value under another name."""
    return st.lists(st.tuples(st.sampled_from(key_paths),
                              st.one_of(values, factors, factors, *more_values),
                              st.one_of(st.none(), st.none(), st.text(min_size=1, max_size=6))),
                    min_size=1, max_size=3)


changes = change_lists(PATHS)


FRAME_SECONDS = 0.5     # examples whose frame is estimated longer are only loaded
FRAME_DEADLINE_MS = 60_000   # a hang, not a slow machine: a new kernel set compiles in 2-9 s


def names_a_key(message: str, touched, key_names) -> bool:
    return ("not valid TOML" in message or any(k in message for k in touched)
            or any(re.search(rf"\b{re.escape(k)}\b", message) for k in key_names))


@settings(max_examples=100, deadline=FRAME_DEADLINE_MS, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                  HealthCheck.too_slow])
@given(changes=changes)
def test_a_generated_scene_file_runs_a_frame_or_is_refused_naming_a_key(tmp_path, changes):
    scene, touched = mutated(changes)
    runs_a_frame_or_is_refused(tmp_path, scene, touched, KEY_NAMES)


def runs_a_frame_or_is_refused(folder, scene: dict, touched, key_names) -> None:
    """Write `scene` and load it: a SceneError names a key (one touched, or one of
    `key_names`); a scene that loads runs a frame (unless it is announced as slow) with
    finite positions or a SimulationDiverged naming the step."""
    path = folder / "scene.toml"
    path.write_text(document(scene), encoding="utf-8")
    try:
        loaded = load_scene(path)
    except SceneError as err:
        assert names_a_key(str(err), touched, key_names), str(err)
        return
    work = loaded.work(frames=1)
    assert work.steps >= 1 and np.isfinite(work.seconds)
    if work.seconds > FRAME_SECONDS:
        return                     # legal but slow: announced by `ti-cloth run` (test_cli.py)
    use(loaded.precision)
    sim = loaded.build()
    try:
        sim.step(work.steps)
    except tc.SimulationDiverged as err:
        assert re.match(r"simulation diverged at step \d+ ", str(err)), str(err)
        return
    assert np.isfinite(sim.positions()).all()


SQUARE = [[0.0, 0.0], [0.2, 0.0], [0.2, 0.2], [0.0, 0.2]]
GARMENT = {
    "scene": {"name": "fuzz_garment"},
    "simulation": {"integrator": "xpbd", "fps": 30, "duration": 1.0, "sewing": {"speed": 0.5}},
    "bodies": [{"type": "garment", "material": {"density": 0.2}, "seams": [[0, 1, 1, 3]],
                "pinned": ["panel1_edge2"],
                "panels": [{"outline": SQUARE, "edge_length": 0.1, "wrap": 0.3, "flare": 0.1,
                            "translate": [0, 0.5, 0]},
                           {"outline": SQUARE, "edge_length": 0.1, "rotate": [0, 0.1, 0],
                            "translate": [0.25, 0.5, 0]}],
                "attachments": [{"particles": ["panel0_edge2"], "collider": 0,
                                 "release": 0.5}]}],
    "colliders": [{"type": "animated_mesh", "path": "body.npz", "fps": 10, "scale": 1.0,
                   "translate": [0, 0, 0], "thickness": 0.01, "static_friction": 0.3,
                   "edge_contact": "auto"}],
    "camera": {"fov": 40, "direction": [0.5, 0.4, 1]},
    "output": {"width": 64, "height": 48, "supersample": 1},
}
GARMENT_PATHS = [p for p in paths(GARMENT) if isinstance(p[-1], str)]
GARMENT_KEYS = sorted({p[-1] for p in GARMENT_PATHS} | set(KEY_NAMES) | {"outline", "fps"})


def write_body(folder) -> None:
    """The animated collider of GARMENT: a tetrahedron rising under the panels."""
    corners = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.3, 0.0], [0.0, 0.0, 0.3]])
    np.savez(folder / "body.npz", triangles=[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
             positions=np.stack([corners + (0.0, 0.02 * k, 0.0) for k in range(11)]))


garment_changes = change_lists(GARMENT_PATHS)


@settings(max_examples=20, deadline=FRAME_DEADLINE_MS, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(changes=garment_changes)
def test_a_generated_garment_scene_runs_a_frame_or_is_refused_naming_a_key(tmp_path, changes):
    """The same for the keys of garments, sewing, attachments and animated mesh colliders."""
    write_body(tmp_path)
    scene, touched = mutated(changes, GARMENT)
    runs_a_frame_or_is_refused(tmp_path, scene, touched, GARMENT_KEYS)


FABRIC = {
    "scene": {"name": "fuzz_fabric"},
    "simulation": {"integrator": "implicit_euler", "fps": 30, "duration": 1.0, "resolution": 2,
                   "self_collision": {"thickness": 0.02, "friction": 0.2, "iterations": 4}},
    "bodies": [{"type": "grid", "rows": 4, "cols": 5, "size": [0.3, 0.3], "pinned": ["top"],
                "warp": [1, 0, 0],
                "fabric": {"preset": "denim", "stretch": [300, 200], "bending": [1e-4, 2e-4],
                           "shear": 20, "poisson": 0.3, "damping": 0.01, "density": 0.3,
                           "hem_mass": 0.0}}],
    "camera": {"fov": 40, "direction": [0.5, 0.4, 1]},
    "output": {"width": 64, "height": 48, "supersample": 1},
}
FABRIC_PATHS = [p for p in paths(FABRIC) if isinstance(p[-1], str)] + [("bodies", 0, "fabric")]
FABRIC_KEYS = sorted({p[-1] for p in FABRIC_PATHS if isinstance(p[-1], str)} | set(KEY_NAMES)
                     | {"material"})
fabric_changes = change_lists(FABRIC_PATHS, st.sampled_from(sorted(tc.FABRICS) + ["silk", "uv"]))


@settings(max_examples=40, deadline=FRAME_DEADLINE_MS, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(changes=fabric_changes)
def test_a_generated_fabric_scene_runs_a_frame_or_is_refused_naming_a_key(tmp_path, changes):
    """The same for the keys of fabrics (a preset by name, a table of moduli, warp), a
    resolution and self-collision of a Fabric (its flat sheet bends by the isometric model)."""
    scene, touched = mutated(changes, FABRIC)
    runs_a_frame_or_is_refused(tmp_path, scene, touched, FABRIC_KEYS)


def test_the_unmutated_fuzz_scene_loads(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(document(BASE))
    assert load_scene(path).cloth.particle_count == 36
    write_body(tmp_path)
    path.write_text(document(GARMENT))
    garment = load_scene(path)
    assert len(garment.cloth.seam_indices) > 0 and len(garment.handles) == 1
    assert isinstance(garment.colliders[0], tc.AnimatedMeshCollider)
    path.write_text(document(FABRIC))
    fabric = load_scene(path)
    assert fabric.cloth.face_count > 0 and fabric.self_collision is not None


numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                    st.integers(min_value=-2**70, max_value=2**70), st.booleans(), st.none(),
                    st.text(max_size=3), st.lists(st.floats(), max_size=4))
small_counts = st.one_of(st.integers(min_value=-3, max_value=12), st.sampled_from([10**9, 2**70]),
                         st.floats(), st.booleans(), st.text(max_size=2))

API = {
    "SpringParams": (lambda a, b: tc.SpringParams(a, b), ("SpringParams",), (numbers, numbers)),
    "Material": (lambda a, b: tc.Material(density=a, hem_mass=b), ("Material",), (numbers, numbers)),
    "grid_mesh": (lambda a, b: tc.grid_mesh(a, b), ("rows", "cols"), (small_counts, small_counts)),
    "string": (lambda a, b: tc.string(a, b), ("n", "length"), (small_counts, numbers)),
    "hair": (lambda a, b: tc.hair(a, 3, b), ("strands", "length"), (small_counts, numbers)),
    "tet_block": (lambda a, b: tc.tet_block(cells=(a, 2, 2), size=(b, 1, 1)), ("cells", "size"),
                  (small_counts, numbers)),
    "Wind": (lambda a, b: tc.Wind(velocity=(a, 0, 0), seed=b), ("Wind",), (numbers, numbers)),
    "Sphere": (lambda a, b: tc.Sphere(radius=a, thickness=b), ("Sphere",), (numbers, numbers)),
    "Plane": (lambda a, b: tc.Plane(point=(0, a, 0), normal=(0, 1, b)), ("Plane",), (numbers, numbers)),
    "StrainLimit": (lambda a, b: tc.StrainLimit(max_strain=a, passes=b), ("StrainLimit",),
                    (numbers, small_counts)),
    "PBD": (lambda a, b: tc.PBD(iterations=a, damping=b), ("PBD",), (small_counts, numbers)),
    "XPBD": (lambda a, b: tc.XPBD(iterations=a), ("XPBD",), (small_counts, numbers)),
    "ImplicitEuler": (lambda a, b: tc.ImplicitEuler(tolerance=a, max_iterations=b),
                      ("ImplicitEuler",), (numbers, small_counts)),
    "Oscillation": (lambda a, b: tc.Oscillation((a, 0, 0), b), ("Oscillation",), (numbers, numbers)),
    "Tearing": (lambda a, b: tc.Tearing(a), ("Tearing",), (numbers, numbers)),
    "stable_dt": (lambda a, b: tc.stable_dt(tc.string(4, 1.0), "verlet", drag=a), ("drag",),
                  (numbers, numbers)),
    "panel": (lambda a, b: tc.panel([(0, 0), (a, 0), (0.2, 0.2)], b), ("outline", "edge_length"),
              (numbers, numbers)),
    "Panel.wrapped": (lambda a, b: tc.panel(SQUARE, 0.1).wrapped(a, b), ("Panel.wrapped",),
                      (numbers, numbers)),
    "Garment": (lambda a, b: tc.Garment([tc.panel(SQUARE, 0.1)] * 2, [(0, a, 1, b)]),
                ("seams",), (small_counts, small_counts)),
    "Sewing": (lambda a, b: tc.Sewing(speed=a), ("Sewing",), (numbers, numbers)),
    "Attachment": (lambda a, b: tc.Attachment([a], tc.Sphere(), release=b), ("Attachment",),
                   (small_counts, numbers)),
    "AnimatedMeshCollider": (lambda a, b: tc.AnimatedMeshCollider(
        tc.sphere_mesh(0.1, subdivisions=0), [[[a, 0.0, 0.0]] * 12] * 2, fps=b),
        ("AnimatedMeshCollider",), (numbers, numbers)),
    "Fabric": (lambda a, b: tc.Fabric(stretch=a, bending=b), ("stretch", "bending"),
               (numbers, numbers)),
    "Fabric.moduli": (lambda a, b: tc.Fabric(shear=a, poisson=b), ("shear", "poisson"),
                      (numbers, numbers)),
    "Fabric.preset": (lambda a, b: tc.Fabric.preset(a, density=b), ("preset", "density"),
                      (st.one_of(st.sampled_from(sorted(tc.FABRICS)), st.text(max_size=6),
                                 numbers), numbers)),
    "Cloth.warp": (lambda a, b: tc.Cloth(tc.grid_mesh(3, 3), tc.Fabric(), warp=(a, 0.0, b)),
                   ("warp",), (numbers, numbers)),
    "SelfCollision": (lambda a, b: tc.SelfCollision(thickness=a, friction=b),
                      ("SelfCollision",), (numbers, numbers)),
    "viewer_for": (lambda a, b: viewer_for(viewed(), width=a, height=b), ("width", "height"),
                   (small_counts, st.one_of(small_counts, st.sampled_from([16, 4096, 4097])))),
    "AnimatedMeshCollider.edge_contact": (lambda a, b: tc.AnimatedMeshCollider(
        tc.sphere_mesh(0.1, subdivisions=0), edge_contact=a, thickness=b),
        ("AnimatedMeshCollider",), (numbers, numbers)),
}


def viewed() -> tc.Simulation:
    """One small simulation for the viewer_for examples of one Taichi runtime (a new one each
    would compile)."""
    use("f64")
    if getattr(viewed, "runtime", None) != backend.generation():
        viewed.sim = tc.Simulation(tc.Cloth(tc.grid_mesh(3, 3), tc.Material()))
        viewed.runtime = backend.generation()
    return viewed.sim


@pytest.mark.parametrize("name", sorted(API))
def test_generated_api_arguments_construct_or_raise_value_error_naming_the_argument(name):
    make, fields, (first, second) = API[name]

    @settings(max_examples=40, deadline=5000, derandomize=True)
    @given(a=first, b=second)
    def check(a, b):
        try:
            make(a, b)
        except ValueError as err:
            assert any(f in str(err) for f in fields), str(err)

    check()
