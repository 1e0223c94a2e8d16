r"""Focus breathing of a fixed render: a plate rendered at one field of view, shown as the lens
focused at the camera's depth sees it.

A lens focused closer images the scene larger: the pinhole camera that images like it has the focal
length F = :attr:`clpost.camera.Camera.render_focal_length_mm` (v for a thin lens, the paraxial
chief-ray gain for a traced lens; docs/conventions.md "Focus"). A plate rendered with a pinhole of
focal length F_p (``--plate-fov infinity``: the lens focused at infinity, F_p = F(∞), as a renderer
set to the lens's focal length does) is the focused image scaled by F_p / F about the principal
point, so each output pixel x reads the plate at

.. math:: x_p = c + (x - c)\,F_p / F

(exact for chief rays: both cameras are pinholes at the entrance pupil, tan θ = (x − c) p / F).
This is an input conversion, done once per frame on the host before the stages (they all measure
in the focused camera's pixels): colour by cubic B-spline interpolation (``scipy.ndimage``,
``order=3``, Unser 1999 — the distortion stage's final filter) clamped below at 0 (no negative
lobes on HDR values); alpha bilinear; depth, velocity and label planes at the nearest plate pixel
(depth is the scene's, unchanged; velocity in px scales by F / F_p; labels never blended). Output
pixels whose source lies outside the plate (F_p > F) get colour 0, alpha 0, depth +inf, labels 0.
"""
from __future__ import annotations

import math

import numpy as np

PLATE_FOVS = ("focused", "infinity")


def plate_focal_length_mm(camera) -> float:
    """Focal length (mm) of the pinhole the plate was rendered with, by ``camera.plate_fov``:
    ``focused`` — the camera's own at its focus (no rescale); ``infinity`` — the lens at infinity."""
    if camera.plate_fov == "focused":
        return camera.render_focal_length_mm
    return camera.with_(focus_distance_m=math.inf, plate_fov="focused").render_focal_length_mm


def magnification(camera) -> float:
    """F / F_p: how much larger the focused image is than the plate (1 for ``focused``)."""
    return camera.render_focal_length_mm / plate_focal_length_mm(camera)


def source_positions(size: tuple[int, int], scale: float, centre: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """(x_p, y_p) float64 (H, W): where each output pixel reads the plate (module docstring)."""
    w, h = size
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    cx, cy = centre
    return cx + (xx - cx) / scale, cy + (yy - cy) / scale


def rescale_plate(frame, camera):
    """``frame`` as the camera focused at its depth sees it (module docstring); the frame itself when
    ``camera.plate_fov`` is ``focused`` or the scale is 1."""
    from scipy import ndimage

    s = magnification(camera)
    if s == 1.0:
        return frame
    k = frame.metadata.get("intrinsics") if isinstance(frame.metadata, dict) else None
    centre = (float(k[2]), float(k[3])) if k is not None else (0.5 * (frame.width - 1), 0.5 * (frame.height - 1))
    xp, yp = source_positions(frame.size, s, centre)
    inside = (xp >= -0.5) & (xp <= frame.width - 0.5) & (yp >= -0.5) & (yp <= frame.height - 0.5)
    coords = np.stack([yp, xp])

    def sample(plane, order):
        return ndimage.map_coordinates(np.asarray(plane, np.float64), coords, order=order, mode="nearest",
                                       prefilter=order > 1)

    color = np.stack([np.maximum(sample(frame.color[..., c], 3), 0.0) for c in range(frame.color.shape[-1])], -1)
    color[~inside] = 0.0
    changes = {"color": color.astype(np.float32)}
    if frame.alpha is not None or not inside.all():
        a = np.ones(frame.size[::-1]) if frame.alpha is None else np.clip(sample(frame.alpha, 1), 0.0, 1.0)
        changes["alpha"] = np.where(inside, a, 0.0).astype(np.float32)
    if frame.depth is not None:
        changes["depth"] = np.where(inside, sample(frame.depth, 0), np.inf).astype(np.float32)
    if frame.velocity is not None:
        v = np.stack([sample(frame.velocity[..., c], 0) for c in range(2)], -1) * s
        changes["velocity"] = np.where(inside[..., None], v, 0.0).astype(np.float32)
    if frame.labels:  # nearest, never blended (clpost.labels.channels); 0 outside the plate
        from .labels.channels import nearest_labels

        xi = np.clip(np.rint(xp), 0, frame.width - 1).astype(np.intp)
        yi = np.clip(np.rint(yp), 0, frame.height - 1).astype(np.intp)
        changes["labels"] = nearest_labels(frame.labels, yi * frame.width + xi, inside)
    meta = dict(frame.metadata)
    if k is not None:
        meta["intrinsics"] = (float(k[0]) * s, float(k[1]) * s, centre[0], centre[1])
    meta["plate_magnification"] = s
    return frame.replace(metadata=meta, **changes)
