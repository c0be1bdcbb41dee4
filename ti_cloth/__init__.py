"""ti_cloth: mass-spring cloth, strings, hair and soft bodies in Taichi.

Nothing here calls ti.init; call ti_cloth.init(arch=..., precision=...) first.
"""
import importlib

from .body.bodies import hair, soft_body, string, tet_block
from .body.fabric import PRESETS as FABRICS
from .body.fabric import Fabric
from .body.material import PRESETS, Material, SpringKind, SpringParams
from .body.mesh import (
    Mesh,
    box_mesh,
    combine_meshes,
    disc_mesh,
    grid_mesh,
    load_mesh,
    save_mesh,
    sphere_mesh,
    tet_grid_mesh,
)
from .body.panels import Garment, Panel, panel
from .body.topology import Cloth
from .contact.colliders.animated_mesh import AnimatedMeshCollider
from .contact.colliders.attachment import Attachment
from .contact.colliders.mesh_collider import MeshCollider
from .contact.colliders.shapes import Box, Capsule, Collider, Plane, Sphere
from .contact.self_collision import SelfCollision, SelfContacts
from .errors import OutputError, SimulationDiverged, StateMismatch, TeamStalled
from .export import Exporter
from .integrators import (
    INTEGRATORS,
    PBD,
    RK4,
    XPBD,
    ExplicitEuler,
    ImplicitEuler,
    ImplicitMidpoint,
    Integrator,
    SymplecticEuler,
    TRBDF2,
    Verlet,
)
from .model import Model
from .physics.forces import ForceSettings
from .physics.handles import Handle
from .physics.paths import Keyframes, Oscillation
from .physics.sewing import Sewing
from .physics.strain_limit import StrainLimit
from .physics.tearing import Tearing
from .physics.wind import Wind
from .runtime.backend import init
from .simulation import Simulation
from .stability import AUTO_MAX_DT, auto_dt, auto_substeps, stable_dt
from .state import State

__all__ = [
    "init", "AnimatedMeshCollider", "Box", "Capsule", "Collider", "Exporter", "MeshCollider", "Plane", "Sphere", "OutputError", "SimulationDiverged", "StateMismatch",
    "TeamStalled",
    "ForceSettings",
    "INTEGRATORS", "Integrator", "ExplicitEuler", "SymplecticEuler", "Verlet", "PBD", "XPBD",
    "ImplicitEuler", "ImplicitMidpoint", "TRBDF2", "RK4", "PRESETS", "FABRICS", "Fabric", "Material", "SpringKind", "SpringParams", "Mesh", "grid_mesh",
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
    """The application layer (ti_cloth.app) pulls in the renderer, so load_scene, run_scene,
    advise, view and its modules (ti_cloth.study, ...; they lived here before ti_cloth.app) are imported
    only when used."""
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
