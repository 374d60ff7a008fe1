"""Headless rendering: cameras (camera.py) draw the scene's shapes (visuals.py) with a software
rasterizer (rasterizer.py) and record videos (recorder.py)."""
from .camera import Camera

__all__ = ["Camera"]
