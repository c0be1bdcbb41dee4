"""ti_cloth: mass-spring cloth, strings, hair and soft bodies in Taichi.

Nothing here calls ti.init; call ti_cloth.init(arch=..., precision=...) first.
"""
import importlib

# every public name and the module that holds it: imported on first use (PEP 562), so
# `import ti_cloth` (and the ti-cloth command's --help and --version) import no Taichi
LAZY = {
    "hair": (".body.bodies", "hair"),
    "soft_body": (".body.bodies", "soft_body"),
    "string": (".body.bodies", "string"),
    "tet_block": (".body.bodies", "tet_block"),
    "FABRICS": (".body.fabric", "PRESETS"),
    "Fabric": (".body.fabric", "Fabric"),
    "BendingCurve": (".body.bending_curve", "BendingCurve"),
    "PRESETS": (".body.material", "PRESETS"),
    "Material": (".body.material", "Material"),
    "SpringKind": (".body.material", "SpringKind"),
    "SpringParams": (".body.material", "SpringParams"),
    "Mesh": (".body.mesh", "Mesh"),
    "box_mesh": (".body.mesh", "box_mesh"),
    "combine_meshes": (".body.mesh", "combine_meshes"),
    "disc_mesh": (".body.mesh", "disc_mesh"),
    "grid_mesh": (".body.mesh", "grid_mesh"),
    "load_mesh": (".body.mesh", "load_mesh"),
    "save_mesh": (".body.mesh", "save_mesh"),
    "sphere_mesh": (".body.mesh", "sphere_mesh"),
    "tet_grid_mesh": (".body.mesh", "tet_grid_mesh"),
    "Garment": (".body.panels", "Garment"),
    "Panel": (".body.panels", "Panel"),
    "panel": (".body.panels", "panel"),
    "Cloth": (".body.topology", "Cloth"),
    "AnimatedMeshCollider": (".contact.colliders.animated_mesh", "AnimatedMeshCollider"),
    "Attachment": (".contact.colliders.attachment", "Attachment"),
    "MeshCollider": (".contact.colliders.mesh_collider", "MeshCollider"),
    "Box": (".contact.colliders.shapes", "Box"),
    "Capsule": (".contact.colliders.shapes", "Capsule"),
    "Collider": (".contact.colliders.shapes", "Collider"),
    "Plane": (".contact.colliders.shapes", "Plane"),
    "Sphere": (".contact.colliders.shapes", "Sphere"),
    "AUTO_THICKNESS": (".contact.colliders.shapes", "AUTO_THICKNESS"),
    "SelfCollision": (".contact.self_collision", "SelfCollision"),
    "SelfContacts": (".contact.self_collision", "SelfContacts"),
    "OutputError": (".errors", "OutputError"),
    "SimulationDiverged": (".errors", "SimulationDiverged"),
    "StateMismatch": (".errors", "StateMismatch"),
    "TeamStalled": (".errors", "TeamStalled"),
    "Exporter": (".export", "Exporter"),
    "INTEGRATORS": (".integrators", "INTEGRATORS"),
    "PBD": (".integrators", "PBD"),
    "RK4": (".integrators", "RK4"),
    "StabilizedRK2": (".integrators", "StabilizedRK2"),
    "XPBD": (".integrators", "XPBD"),
    "ExplicitEuler": (".integrators", "ExplicitEuler"),
    "ImplicitEuler": (".integrators", "ImplicitEuler"),
    "ImplicitMidpoint": (".integrators", "ImplicitMidpoint"),
    "Integrator": (".integrators", "Integrator"),
    "SymplecticEuler": (".integrators", "SymplecticEuler"),
    "TRBDF2": (".integrators", "TRBDF2"),
    "Verlet": (".integrators", "Verlet"),
    "Model": (".model", "Model"),
    "ForceSettings": (".physics.forces", "ForceSettings"),
    "Handle": (".physics.handles", "Handle"),
    "Keyframes": (".physics.paths", "Keyframes"),
    "Oscillation": (".physics.paths", "Oscillation"),
    "Sewing": (".physics.sewing", "Sewing"),
    "StrainLimit": (".physics.strain_limit", "StrainLimit"),
    "Tearing": (".physics.tearing", "Tearing"),
    "Wind": (".physics.wind", "Wind"),
    "init": (".runtime.backend", "init"),
    "Simulation": (".simulation", "Simulation"),
    "AUTO_MAX_DT": (".stability", "AUTO_MAX_DT"),
    "auto_dt": (".stability", "auto_dt"),
    "auto_substeps": (".stability", "auto_substeps"),
    "stable_dt": (".stability", "stable_dt"),
    "State": (".state", "State"),
}

__all__ = [
    "init", "AnimatedMeshCollider", "Box", "Capsule", "Collider", "Exporter", "MeshCollider", "Plane", "Sphere", "AUTO_THICKNESS", "OutputError", "SimulationDiverged", "StateMismatch",
    "TeamStalled",
    "ForceSettings",
    "INTEGRATORS", "Integrator", "ExplicitEuler", "SymplecticEuler", "Verlet", "PBD", "XPBD",
    "ImplicitEuler", "ImplicitMidpoint", "TRBDF2", "RK4", "StabilizedRK2", "PRESETS", "FABRICS", "Fabric", "BendingCurve", "Material", "SpringKind", "SpringParams", "Mesh", "grid_mesh",
    "box_mesh", "combine_meshes", "disc_mesh", "sphere_mesh",
    "tet_grid_mesh", "load_mesh", "save_mesh", "Model", "Keyframes", "Oscillation", "Handle",
    "Attachment", "panel", "Panel", "Garment", "Sewing",
    "Simulation", "stable_dt", "auto_dt", "auto_substeps", "AUTO_MAX_DT", "State", "StrainLimit", "SelfCollision",
    "SelfContacts",
    "Tearing", "Cloth", "Wind", "string", "hair", "soft_body", "tet_block",
]


# modules that were ti_cloth.<name>, and where they are now
MOVED_MODULES = {"scene": "app.scene", "scene_file": "inputs.scene_file", "runner": "app.runner",
                 "study": "app.study", "cli": "app.cli"}


def __getattr__(name):
    """Every public name is imported when first used (LAZY): the package imports no Taichi
    until something needs it. The application layer (ti_cloth.app) pulls in the renderer, so
    load_scene, run_scene, advise, view and its modules (ti_cloth.study, ...; they lived here
    before ti_cloth.app) are imported only when used too."""
    if name in LAZY:
        module, attribute = LAZY[name]
        value = getattr(importlib.import_module(module, __name__), attribute)
        globals()[name] = value
        return value
    if name == "load_scene":
        from .app.scene import load_scene
        return load_scene
    if name == "run_scene":
        from .app.runner import run_scene
        return run_scene
    if name == "advise":
        from .app.advisor import advise
        return advise
    if name == "view":
        from .app.view import view
        return view
    if name in MOVED_MODULES:
        return importlib.import_module(f".{MOVED_MODULES[name]}", __name__)
    raise AttributeError(f"module 'ti_cloth' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(LAZY) | set(__all__))
