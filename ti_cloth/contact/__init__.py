"""Contact: colliders/ (analytic shapes, meshes with distance grids, deforming meshes read
from animation files, attachments to their surfaces, and the collision stage that keeps the
cloth out of them), broad_phase/ (the box grid and the candidate pairs it lists), and
self_collision.py (the cloth against itself). The closest points and barycentric coordinates
all of them use are ti_cloth/geometry.py."""
