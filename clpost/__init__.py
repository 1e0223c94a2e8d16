"""clpost — a realistic camera for rendered images.

Takes the color, depth and velocity buffers of any rasterizer and applies the physics of a real
lens and film as data-parallel OpenCL stages. ``Camera`` describes the camera, ``Frame`` holds a
frame's buffers, ``Pipeline`` plans and runs the stages (build once, run many frames).
"""
from .camera import Camera
from .errors import ClpostError, InputError, KernelBuildError, OpenCLUnavailableError
from .frame import Frame
from .pipeline import Pipeline

__all__ = ["Camera", "ClpostError", "Frame", "InputError", "KernelBuildError",
           "OpenCLUnavailableError", "Pipeline"]
__version__ = "0.1.0"
