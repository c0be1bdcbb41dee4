"""A Fabric's elements in implicit Euler's system (implicit_euler.py): the workspace fields of
their linearisation at x_n and of their share of the matrix-free product A p,
A = M + h^2 H + h beta H_GN, and the loops and phases that fill them. The Hessians themselves
are the terms' (energies/membrane.py: the StVK membrane's, its stress projected onto
non-negative eigenvalues; energies/bending.py: the mid-edge bending's Gauss-Newton part, its
product in two loops, every hinge's projection on p then its response; energies/faces.py: the
per-corner products and 3x3 diagonals every particle gathers in the Model's fixed order).
"""

import taichi as ti

from ..energies.bending import (
    hinge_product,
    linearise_hinge,
    project_hinge,
    store_secant,
)
from ..energies.membrane import face_product, linearise_face
from ..runtime import backend
from ..runtime.plan import DT, ITEM, NOW, STATE, Loop, Phase


def add_fields(ws, fields, face_count: int, hinge_count: int) -> None:
    """The linearisation and per-corner products of face_count triangles and hinge_count
    hinges, on the workspace ws (allocated with its FieldGroup)."""
    real = backend.real()
    faces, hinges = max(face_count, 1), max(hinge_count, 1)
    ws.face_warp = fields.vector(3, real, faces)        # F's columns at x_n
    ws.face_weft = fields.vector(3, real, faces)
    ws.face_stress = fields.vector(3, real, faces)      # projected S: s11, s22, s12
    ws.face_product = fields.vector(3, real, 3 * faces)
    ws.face_diagonal = fields.vector(3, real, 3 * faces)
    ws.hinge_gradient = fields.vector(3, real, 4 * hinges)
    ws.hinge_projection = fields.scalar(real, hinges)
    ws.hinge_product = fields.vector(3, real, 4 * hinges)
    ws.hinge_diagonal = fields.vector(3, real, 4 * hinges)
    ws.face_secant = fields.vector(6, real, faces)      # B(k) at x_n (energies/bending_law.py)


@ti.func
def stretch_direction(model: ti.template(), ws: ti.template(), f, now: ti.template()):
    """face_product = triangle f's membrane block of A times p."""
    h = now.dt
    face_product(model, ws, f, ws.p, h * h + h * model.face_damping[f], h * h)


def linear_loops(model, forces, ws) -> tuple:
    """Loops of the first phase (beside the forces): every triangle's linearisation."""
    if not model.face_count:
        return ()
    return (Loop(model.face_count, linearise_face, model, STATE, forces, ws, ITEM, NOW),)


def bending_loops(model, ws) -> tuple:
    """(with the moments, with the hinge forces): energies/bending.bending_phases' extra
    loops that linearise every hinge, and apply its stiffness to v_n (hinge_product)."""
    if not model.hinge_count or model.isometric:
        return (), ()
    secants = ((Loop(model.face_count, store_secant, model, STATE, ws, ITEM),) if model.curved
               else ())
    return ((Loop(model.hinge_count, linearise_hinge, model, STATE, ws, ITEM, NOW),) + secants,
            (Loop(model.hinge_count, hinge_product, model, ws, ITEM, DT, True),))


def product_phases(model, ws, first: tuple) -> tuple:
    """The phases before the particles gather A p: `first` (the caller's loops on p) with every
    triangle's product and every hinge's projection on p, then every hinge's product."""
    loops = first
    if model.face_count:
        loops += (Loop(model.face_count, stretch_direction, model, ws, ITEM, NOW),)
    hinges = model.hinge_count and not model.isometric
    if hinges:
        loops += (Loop(model.hinge_count, project_hinge, model, ws, ITEM, ws.p),)
    phases = (Phase(*loops),) if loops else ()
    if hinges:
        phases += (Phase(Loop(model.hinge_count, hinge_product, model, ws, ITEM, DT, False)),)
    return phases
