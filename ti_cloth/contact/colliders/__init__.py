"""Colliders and the collision stage: analytic shapes (shapes.py), triangle meshes with their
distance grids (mesh_collider.py, sdf.py), deforming meshes (animated_mesh.py, read by
animation_files.py; placed with their boxes each step in animated_bodies.py, the triangles a
path may meet found in candidate_lists.py, continuous contact of particles in
animated_contact.py and of cloth edges in animated_edges.py), attachments to a collider's
surface (attachment.py), and the stage that keeps particles out of a simulation's colliders
(collision.py)."""
