"""Simulated worlds: 2-D polygons with a rigid inner and a soft outer shape."""

from .scene2d import Scene2D, paper_objects_2d, rectangle

__all__ = ["Scene2D", "paper_objects_2d", "rectangle"]
