"""Self-collision's broad phase: a grid of boxes (box_grid.py) and the candidate pairs listed
from it, vertex-triangle and edge-edge (contact_pairs.py)."""
