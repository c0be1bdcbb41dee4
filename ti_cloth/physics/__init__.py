"""The loads and stages of a step around the energy terms: the force evaluation that composes
the terms a model has with gravity, drag and the wind (forces.py), the wind, handles and their
paths, sewing, strain limiting and tearing (each a Stage: ti_cloth/stages.py)."""
