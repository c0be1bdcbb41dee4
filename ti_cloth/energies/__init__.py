"""One module per energy term, each holding together what every solver needs of it: its rest
data from the host mesh, its energy (float64, on the host), its force, its Hessian (blocks or
products, projected to be positive semi-definite) and its position-based projection, with the
equations cited once.

    springs.py     Stuyck's Hookean springs with damping (eq. 4.4-4.7)
    altitude.py    Selle et al. 2008's altitude springs of tetrahedra
    membrane.py    a Fabric's membrane: orthotropic StVK constant-strain triangles
    bending.py     a Fabric's bending: the mid-edge shape operator, in tangents
    isometric.py   a flat Fabric sheet's bending: Bergou et al. 2006's isometric model
    faces.py       what the triangle terms share: deformation gradients, per-corner slots
                   and their gather, XPBD's update of a vector constraint
    tethers.py     Kim et al. 2012's long-range attachments: XPBD's limits on how far a
                   particle strays from its pins (not an energy: XPBD.tethers)

Forces are evaluated once per element into per-element or per-corner slots (each term's
force_loops: the loops of a force evaluation's first phase, none for a model without the
term; the mid-edge bending adds its later phases, bending_phases) and gathered per particle
in a fixed order (each slot kind's gather), so runs are deterministic; physics/forces.py
runs them in the order of TERMS and SLOTS, implicit Euler its rows in the order of ROWS, xpbd
its sweeps in the order of PROJECTIONS. A new term is a module here and a line in TERMS and
PROJECTIONS (and one in SLOTS and ROWS if it brings a kind of slot of its own). This package
sits below body/ (which builds a Cloth's rest data with it) and imports only geometry.py,
inputs/ and runtime/.
"""

from . import altitude, bending, faces, isometric, membrane, springs, tethers

# the terms a force evaluation visits, in this order (their force_loops)
TERMS = (springs, altitude, membrane, isometric, bending)
# the per-particle gathers of the terms' force slots, in this order (their gather): springs',
# altitude springs', the triangle terms' corners (faces.py)
SLOTS = (springs, altitude, faces)
# the rows of implicit Euler's system, in this order (implicit_start: K v_n and A's 3x3
# diagonal; implicit_product: A p): springs', altitude springs', the triangle terms' (faces.py),
# the isometric bending's
ROWS = (springs, altitude, faces, isometric)
# the terms XPBD sweeps, in this order (their xpbd_nodes: loops clearing their multipliers,
# sweeps colour by colour); the tethers last, where XPBD has them
PROJECTIONS = (springs, altitude, membrane, bending, isometric, tethers)
