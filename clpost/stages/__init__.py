"""The stage registry: every module here that defines a :class:`~clpost.stages.base.Stage`
subclass contributes one stage — adding a stage touches no other stage; it adds one line to
:data:`STAGE_ROLES` (where light reaches it) and regenerates the table below.

Physical order (light from the scene through the lens to the recorded image): the explicit list
:data:`PHYSICAL_ORDER`, which each stage's ``order`` must follow (``tests/test_stage_order.py``).
The table below is generated from it by ``python tools/gen_stage_table.py``; do not edit it by hand.

.. stage-order-table: begin

====  =============  =========================================================================
10    dof            defocus: depends on scene depth, in the undistorted render's image space
20    astigmatism    field-dependent directional blur (sagittal/tangential focus)
25    coma           field-dependent asymmetric PSF
30    lateral_color  per-channel radial magnification
40    motion_blur    integration over the shutter; velocity is in undistorted pixel space
50    distortion     resampling from the undistorted render into the distorted image
60    vignetting     fixed to the sensor, so after everything that moves image content
70    exposure       luminance → exposure → normalised sensor signal (linear)
80    film           the film's response: characteristic curves, exposure → density
85    sensor         a digital sensor's response: shot and read noise, full well, quantisation
90    grain          noise of the film, on its densities
95    print          negative → paper print (or re-linearised), the last step
====  =============  =========================================================================

.. stage-order-table: end

Linear pointwise stages (vignetting, exposure) commute with the linear blurs; where a
stage is non-linear (film, sensor clipping, grain, print) its position matters and is as above.
"""
from __future__ import annotations

import importlib
import inspect
import pkgutil
from functools import lru_cache

from .base import QUALITIES, GatherStage, PointwiseStage, Stage

__all__ = ["PHYSICAL_ORDER", "QUALITIES", "STAGE_ROLES", "GatherStage", "PointwiseStage", "Stage", "order_table",
           "registry", "stage_names"]

#: Every stage, in the physical order of light through the camera, with why it sits there. A new
#: stage is added here; its class's ``order`` must fall between its neighbours' (checked by
#: ``tests/test_stage_order.py``), and the table in this module's docstring is generated from it.
STAGE_ROLES: tuple[tuple[str, str], ...] = (
    ("dof", "defocus: depends on scene depth, in the undistorted render's image space"),
    ("astigmatism", "field-dependent directional blur (sagittal/tangential focus)"),
    ("coma", "field-dependent asymmetric PSF"),
    ("lateral_color", "per-channel radial magnification"),
    ("motion_blur", "integration over the shutter; velocity is in undistorted pixel space"),
    ("distortion", "resampling from the undistorted render into the distorted image"),
    ("vignetting", "fixed to the sensor, so after everything that moves image content"),
    ("exposure", "luminance → exposure → normalised sensor signal (linear)"),
    ("film", "the film's response: characteristic curves, exposure → density"),
    ("sensor", "a digital sensor's response: shot and read noise, full well, quantisation"),
    ("grain", "noise of the film, on its densities"),
    ("print", "negative → paper print (or re-linearised), the last step"),
)

#: Stage names in physical order (the names of :data:`STAGE_ROLES`).
PHYSICAL_ORDER: tuple[str, ...] = tuple(name for name, _ in STAGE_ROLES)


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


def order_table() -> str:
    """The reStructuredText table of :data:`STAGE_ROLES` with each stage's ``order``, as this
    module's docstring holds it (regenerate with ``python tools/gen_stage_table.py``)."""
    reg = registry()
    rows = [(f"{reg[name].order:g}" if name in reg else "?", name, role) for name, role in STAGE_ROLES]
    widths = [max(4, *(len(r[i]) for r in rows)) for i in range(2)]
    rule = "  ".join(["=" * widths[0], "=" * widths[1], "=" * max(len(r[2]) for r in rows)])
    body = [f"{o:<{widths[0]}}  {n:<{widths[1]}}  {role}" for o, n, role in rows]
    return "\n".join([rule, *body, rule])
