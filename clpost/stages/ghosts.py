r"""ghosts: the lens's two-reflection ghosts of the frame's brightest sources.

**Model** (formulas and sources in :mod:`clpost.optics.ghosts`): every pair of surfaces of the
traced prescription (focused, stopped to the working f-number) gives a first-order ghost — the
aperture shape (blades, rotation, roundness as the DoF stage's, :func:`clpost.stages.dof.aperture_radius`)
scaled by :math:`m_g` and centred at :math:`s_g\,p` for a source at p (image position from the
optical centre), carrying the share :math:`\rho_g` (coating reflectances × beam ratio) of the
source's flux, per channel at the channel's wavelength (611, 549, 464 nm: the coatings tint the
ghosts). Radii below 1 px are raised to 1 px.

**Sources.** A pixel whose largest channel exceeds the threshold
:math:`T = \texttt{ghost\_threshold} / g` (g the exposure gain: T is ``ghost_threshold`` times the
scene value that saturates the sensor; :func:`clpost.photometry.exposure_gain`) belongs to a
source. The frame is cut into 16 × 16 tiles; the tiles holding the most flux above threshold (the
sum of their above-threshold pixels' luminance; at most ``ghost_sources``) are the sources, each
at its above-threshold pixels' luminance-weighted centroid with their summed RGB flux. The sources
are found on the host from the frame's input pixels (one pass, ~5 ms at 960 × 540), so the stage
runs in the render's geometry, before distortion (which then moves the ghosts with the image:
a first-order ghost carries no distortion of its own).

**Energy.** A source's above-threshold pixels keep :math:`1 - \sum_g \rho_g` of their value; each
ghost spreads :math:`\rho_g` of the source's flux over its area (the 1-px coverage ramp of the
DoF stage, normalised by the shape's area :math:`a_K R^2`), so the frame's total is conserved
except for ghost light that falls outside the frame (tested to 1 %).

**Planned** only when ``Camera.ghosts`` is on, the lens is a traced prescription and some pixel
exceeds T (``--explain`` names the brightest pixel in saturations).

Quality: the ghosts kept, brightest first by peak irradiance :math:`\rho_g/(a_K R_g^2)`: draft 8,
preview 24, final all (78 for the Planar).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..params import at_least, boolean, integer, param, parse_fraction, parse_on_off
from . import _field as fld
from .base import GatherStage, per_camera

TILE = 16
MIN_RADIUS_PX = 1.0
GHOSTS_KEPT = {"draft": 8, "preview": 24, "final": None}
SRC_REC = 8
"""Floats per source: x, y (px), flux R, G, B, tile x0, y0, 0."""
GHOST_REC = 12
"""Floats per ghost: per channel (centre factor, signed radius px, irradiance per unit flux), padded."""


@dataclass(frozen=True)
class GhostsParams:
    """ghosts: first-order two-reflection ghosts of a traced lens, driven by the frame's bright sources."""

    ghosts: bool = param(False, unit="on/off", flag="--ghosts", parse=parse_on_off, check=boolean,
                         header="clpost.ghosts", scalar=False,
                         help="lens ghosts of the brightest sources (a lens_data lens): on/off")
    ghost_threshold: float = param(
        1.0, unit="× saturation", flag="--ghost-threshold", parse=parse_fraction, header="clpost.ghostThreshold",
        check=at_least(0.0, "× saturation", "e.g. 1 (sources that clip the sensor)", "0 = every pixel"),
        scalar=True, help="a source is a pixel brighter than this many times the exposure's saturation")
    ghost_sources: int = param(8, unit="sources", flag="--ghost-sources", parse=int,
                               check=integer(1, 257, rule="an integer from 1 to 256"), header="clpost.ghostSources",
                               scalar=False, help="at most this many sources throw ghosts (brightest first)")


def threshold_scene(camera) -> float:
    """T: the scene value of ``ghost_threshold`` saturations (module docstring)."""
    from ..photometry import exposure_gain

    return camera.ghost_threshold / exposure_gain(camera)


def find_sources(color: np.ndarray, threshold: float, max_sources: int, tile: int = TILE) -> np.ndarray:
    """(K, SRC_REC) float64 sources of the module docstring, brightest first (K ≤ max_sources)."""
    c = np.asarray(color, np.float64)
    h, w = c.shape[:2]
    over = c.max(axis=2) > threshold
    if not over.any():
        return np.zeros((0, SRC_REC))
    ty, tx = np.nonzero(over)
    lum = c[ty, tx] @ np.array([0.2126, 0.7152, 0.0722])
    tid = (ty // tile) * ((w + tile - 1) // tile) + tx // tile
    n_t = ((h + tile - 1) // tile) * ((w + tile - 1) // tile)
    tot = np.bincount(tid, lum, n_t)
    order = np.argsort(-tot, kind="stable")
    order = order[tot[order] > 0][:max_sources]
    out = np.zeros((len(order), SRC_REC))
    for k, t in enumerate(order):
        sel = tid == t
        wgt = lum[sel] / tot[t]
        out[k, 0], out[k, 1] = (tx[sel] * wgt).sum(), (ty[sel] * wgt).sum()
        out[k, 2:5] = c[ty[sel], tx[sel]].sum(axis=0)
        out[k, 5], out[k, 6] = (t % ((w + tile - 1) // tile)) * tile, (t // ((w + tile - 1) // tile)) * tile
    return out


class Ghosts(GatherStage):
    name = "ghosts"
    order = 45.0
    role = "light reflected twice between lens surfaces, imaged through the aperture (before distortion: it finds its sources in the render's pixels)"
    domains = ("render", "render")
    params = GhostsParams
    example = dict(lens="zeiss-planar-50-f1.4", f_number=4.0, ghosts=True, ghost_threshold=0.5,
                   ghost_sources=4, blades=6)
    turn_off = "give --ghosts off"

    @per_camera
    def table(self, camera, width: int) -> np.ndarray:
        """(G, GHOST_REC) float64 ghosts kept at this quality (module docstring), brightest first:
        per channel centre factor, signed radius (px; < 0 turned 180°) and irradiance per unit
        flux (1/px²); column 9: the ghost's path i*100 + j."""
        from ..optics.ghosts import ghosts
        from .dof import aperture_area
        from .lateral_color import channel_wavelengths_nm

        lens = camera.optics
        n = lens.clamp_f_number(camera.f_number, warn=False)
        pres = lens.focused(camera.focus_from_film_m * 1000.0, n)
        r_stop = lens.stop_radius_mm(n)
        pitch = fld.pitch_mm(camera, width)
        a_k = aperture_area(camera.blades, 0.0, camera.aperture_roundness)
        per_ch = [ghosts(pres, r_stop, lam) for lam in channel_wavelengths_nm()]
        rows = []
        for gs in zip(*per_ch):
            row = np.zeros(GHOST_REC)
            for c, g in enumerate(gs):
                r_px = max(g.radius_mm / pitch, MIN_RADIUS_PX)
                row[3 * c:3 * c + 3] = (g.centre_factor, math.copysign(r_px, g.scale), g.share / (a_k * r_px * r_px))
            row[9] = gs[0].path[0] * 100 + gs[0].path[1]
            row[10] = sum(g.share for g in gs) / 3.0
            rows.append(row)
        rows.sort(key=lambda r: -r[5])  # green peak irradiance
        kept = GHOSTS_KEPT[self.quality]
        return np.array(rows[:kept] if kept else rows)

    def shares(self, camera, width: int) -> np.ndarray:
        """Σ ρ_g per channel over the kept ghosts (what a source's pixels give up)."""
        t = self.table(camera, width)
        return np.array([(t[:, 3 * c + 2] * _area(camera, t[:, 3 * c + 1])).sum() for c in range(3)])

    def sources(self, camera, frame) -> np.ndarray:
        return find_sources(frame.color, threshold_scene(camera), camera.ghost_sources)

    def skip_reason(self, camera, frame):
        if not camera.ghosts:
            return "Camera.ghosts is off"
        if camera.optics is None:
            return "thin lens: no prescription to reflect light (use a lens_data lens)"
        t = threshold_scene(camera)
        peak = float(np.max(frame.color)) if frame.color.size else 0.0
        if not peak > t:
            return (f"no source above the threshold ({camera.ghost_threshold:g} × saturation = {t:.3g}; "
                    f"brightest pixel {peak:.3g})")
        return None

    def reason_needed(self, camera, frame):
        t = threshold_scene(camera)
        s = self.sources(camera, frame)
        g = self.table(camera, fld.image_width_px(frame))
        return (f"{len(s)} source(s) above {camera.ghost_threshold:g} × saturation (brightest pixel "
                f"{float(np.max(frame.color)) / t * camera.ghost_threshold:.3g} × saturation), {len(g)} ghosts, "
                f"Σρ = {self.shares(camera, fld.image_width_px(frame))[1]:.2e} of each source's flux")

    def replay_key(self, camera, frame):
        return (super().replay_key(camera, frame), self.sources(camera, frame).tobytes())

    def defines(self, camera):
        return {"GHOSTS_BLADES": int(camera.blades)}

    def enqueue(self, rt, camera, frame, src, dst, aux):
        from ..runtime import kernel_source

        w, h = frame.width, frame.height
        g = fld.frame_geometry(camera, frame)
        cx, cy = fld.field_centre_px(camera, frame) if g is not None else fld.principal_point_px(camera, w, h)
        table = self.table(camera, fld.image_width_px(frame))
        srcs = self.sources(camera, frame)
        src_buf = rt.scratch(self, "sources", (max(len(srcs), 1), SRC_REC))
        if len(srcs):
            rt.copy(src_buf, np.ascontiguousarray(srcs, np.float32))
        tab = rt.constant(np.ascontiguousarray(table, np.float32), ("ghosts", table.tobytes()))
        keep = 1.0 - self.shares(camera, fld.image_width_px(frame))
        k = rt.kernel(kernel_source("ghosts"), "ghosts", self.defines(camera), "ghosts")
        rot = math.radians(camera.blade_rotation_deg)
        return [rt.launch(k, (w, h), None, src, dst, src_buf, np.int32(len(srcs)), tab, np.int32(len(table)),
                          np.int32(w), np.int32(h), np.float32(cx), np.float32(cy),
                          np.float32(threshold_scene(camera)), np.float32(keep[0]), np.float32(keep[1]),
                          np.float32(keep[2]), np.float32(rot), np.float32(camera.aperture_roundness))]

    def reference(self, camera, frame, color):
        """float64 numpy implementation of the module docstring."""
        from .dof import aperture_radius

        color = np.asarray(color, np.float64)
        h, w = color.shape[:2]
        g = fld.frame_geometry(camera, frame)
        cx, cy = fld.field_centre_px(camera, frame) if g is not None else fld.principal_point_px(camera, w, h)
        table = self.table(camera, fld.image_width_px(frame))
        srcs = self.sources(camera, frame)
        keep = 1.0 - self.shares(camera, fld.image_width_px(frame))
        out = color.copy()
        t = threshold_scene(camera)
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
        over = color.max(axis=2) > t
        for s in srcs:
            in_tile = over & (xs >= s[5]) & (xs < s[5] + TILE) & (ys >= s[6]) & (ys < s[6] + TILE)
            out[in_tile] *= keep
        for s in srcs:
            for row in table:
                for c in range(3):
                    f, r, e = row[3 * c:3 * c + 3]
                    ox = xs - (cx + (s[0] - cx) * f)
                    oy = ys - (cy + (s[1] - cy) * f)
                    if r < 0:
                        ox, oy, r = -ox, -oy, -r
                    rho = aperture_radius(np.arctan2(oy, ox), camera.blades, camera.blade_rotation_deg,
                                          camera.aperture_roundness)
                    cov = np.clip(r * rho - np.hypot(ox, oy) + 0.5, 0.0, 1.0)
                    out[..., c] += s[2 + c] * e * cov
        return out


def _area(camera, r_px) -> np.ndarray:
    from .dof import aperture_area

    return aperture_area(camera.blades, 0.0, camera.aperture_roundness) * np.asarray(r_px) ** 2
