"""Geometric primitives: exact float32 distances between points, edges and triangles.

Submodules are imported explicitly (``pscc.geometry.distance``); this package imports nothing.
"""
