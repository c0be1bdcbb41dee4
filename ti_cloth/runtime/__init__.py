"""Taichi's runtime and what only it needs to know: init and precision, field trees, the pool of kernel arguments, the team of CPU workers, uploads, input limits and checks, atomic files."""
