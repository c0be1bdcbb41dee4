"""Contact: analytic and mesh colliders with their distance grids, the collision stage, and self-collision (broad phase, closest points, candidate pairs, the contact stage)."""
