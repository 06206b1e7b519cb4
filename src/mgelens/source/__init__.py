"""Pixelized source: Voronoi mesh, natural-neighbour interpolation (SPEC §4)."""
