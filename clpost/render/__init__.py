"""Scene renderers that feed clpost: anything with ``render(camera, size, frame_index) -> Frame``.

The default is :class:`PyVistaRenderer` (offscreen VTK rasterization of a procedural
:class:`DemoScene`, linear HDR colour, planar depth and forward velocity); ``clpost demo`` uses
:func:`render_demo_sequence`.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

from ..camera import Camera
from ..frame import Frame
from .demo_scene import DemoScene
from .pyvista_renderer import PyVistaRenderer, render_demo_sequence

__all__ = ["Renderer", "DemoScene", "PyVistaRenderer", "render_demo_sequence"]


@runtime_checkable
class Renderer(Protocol):
    """A rasterizer clpost can post-process.

    ``render`` returns frame ``frame_index`` seen through ``camera`` at ``size`` = (width, height)
    pixels, with the pinhole intrinsics ``camera.intrinsics(width, height)``: a
    :class:`~clpost.frame.Frame` whose colour is linear scene-referred float RGB, depth planar
    metres (+inf background) and velocity forward px per frame (``shared/CONVENTIONS.md``).
    """

    def render(self, camera: Camera, size: tuple[int, int], frame_index: int) -> Frame: ...
