"""The stage registry: every module here that defines a :class:`~clpost.stages.base.Stage`
subclass contributes one stage — adding a stage touches no other stage.

Physical order (light from the scene through the lens to the recorded image); each stage's
``order`` puts it in this sequence:

====  ===============  ==========================================================================
10    dof              defocus: depends on scene depth, in the undistorted render's image space
20    astigmatism      field-dependent directional blur (sagittal/tangential focus)
25    coma             field-dependent asymmetric PSF
30    lateral_color    per-channel radial magnification
40    motion_blur      integration over the shutter; velocity is in undistorted pixel space
50    distortion       resampling from the undistorted render into the distorted image
60    vignetting       fixed to the sensor, so after everything that moves image content
70    exposure         luminance → exposure → normalised sensor signal (linear)
80    film / sensor    the recording medium's response
90    grain            noise of the medium, last
====  ===============  ==========================================================================

Linear pointwise stages (vignetting, exposure) commute with the linear blurs; where a
stage is non-linear (film, sensor clipping, grain) its position matters and is as above.
"""
from __future__ import annotations

import importlib
import inspect
import pkgutil
from functools import lru_cache

from .base import QUALITIES, GatherStage, PointwiseStage, Stage

__all__ = ["QUALITIES", "GatherStage", "PointwiseStage", "Stage", "registry", "stage_names"]


@lru_cache(maxsize=None)
def registry() -> dict[str, type[Stage]]:
    """All stage classes by name, in physical order."""
    found: dict[str, type[Stage]] = {}
    for mod in pkgutil.iter_modules(__path__):
        if mod.name == "base":
            continue
        module = importlib.import_module(f"{__name__}.{mod.name}")
        for obj in vars(module).values():
            if (inspect.isclass(obj) and issubclass(obj, Stage) and not inspect.isabstract(obj)
                    and obj.__module__ == module.__name__):
                if obj.name in found:
                    raise RuntimeError(f"two stages are named {obj.name!r}")
                found[obj.name] = obj
    return dict(sorted(found.items(), key=lambda kv: kv[1].order))


def stage_names() -> list[str]:
    return list(registry())
