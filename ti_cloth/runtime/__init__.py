"""Taichi's runtime and what only it needs to know: init and precision, field trees, the pool
of kernel arguments, the team of CPU workers, the plan runner (a step's phases, launched phase
by phase or shared by the team), uploads."""
