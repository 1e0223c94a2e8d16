r"""Real sequential ray tracing through a prescription (vectorised numpy, float64).

Each surface k has its vertex at z_k on the axis (first vertex at z = 0, light toward +z) and
curvature c = 1/R. With p = o − (0, 0, z_k) a ray o + t·d meets the sphere
:math:`c\,|p + t d|^2 - 2 (p_z + t d_z) = 0` at the root nearest the vertex,

.. math::

    t = \frac{C}{-B + \sqrt{B^2 - cC}} = \frac{-B - \sqrt{B^2 - cC}}{c},\quad
    B = c\,(p\cdot d) - d_z,\quad C = c\,|p|^2 - 2p_z

evaluated in whichever form has no cancellation (the first when −B > 0; it is exact for planes,
c = 0), which also avoids the cancellation of the centre-based formula for large |R|. The unit normal there is :math:`N = (c x, c y, c z - 1)` (toward the object), and
the vector form of Snell's law with μ = n/n' and cos i = −d·N gives

.. math::

    d' = \mu d + \left(\mu\cos i - \sqrt{1 - \mu^2 (1 - \cos^2 i)}\right) N

(Glassner, *An Introduction to Ray Tracing*, §6; pbrt-v4 ``Refract``). A negative radicand is
total internal reflection. Each ray reports its fate (:data:`OK`, :data:`MISS` — no
intersection or travelling backwards, :data:`CLIPPED` — outside a clear semi-diameter,
:data:`STOP` — blocked by the aperture stop, :data:`TIR`) and the 0-based surface where it
happened; failed rays keep their last finite position and direction, so no NaN leaves here.

``kernels/lens_trace.cl`` is the same algorithm in OpenCL (double precision) for large bundles;
:func:`trace_cl` runs it and the tests require equality with :func:`trace` to 1e-12 mm.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .prescription import LAMBDA_D_NM, Prescription

OK, MISS, CLIPPED, STOP, TIR = 0, 1, 2, 3, 4
STATUS_NAMES = {OK: "ok", MISS: "miss", CLIPPED: "clipped", STOP: "stop", TIR: "tir"}


@dataclass
class TraceResult:
    """Rays at the film plane (or where they failed). Lengths in mm, z from the first vertex."""

    pos: np.ndarray  # (N, 3)
    dir: np.ndarray  # (N, 3) unit vectors
    status: np.ndarray  # (N,) int8, OK/MISS/CLIPPED/STOP/TIR
    surface: np.ndarray  # (N,) int16, 0-based surface of failure, -1 if OK (len(surfaces) = film)
    stop_xy: np.ndarray  # (N, 2) where each ray crossed the stop plane (NaN-free: 0 if never reached)

    @property
    def ok(self) -> np.ndarray:
        return self.status == OK


def surface_table(pres: Prescription, wavelength_nm: float = LAMBDA_D_NM, clip: bool = True,
                  stop_radius_mm: float | None = None) -> np.ndarray:
    """(S, 5) float64 rows: vertex z, curvature, semi-diameter (inf if not clipping), index
    after, is-stop. The layout the OpenCL kernel reads."""
    n = pres.indices(wavelength_nm)
    zs = pres.vertex_z
    rows = []
    for k, s in enumerate(pres.surfaces):
        sd = s.semi_diameter_mm
        if s.stop and stop_radius_mm is not None:
            sd = stop_radius_mm
        if not clip and not s.stop:
            sd = np.inf
        if not clip and s.stop:
            sd = np.inf
        rows.append((zs[k], s.curvature, sd, n[k], 1.0 if s.stop else 0.0))
    return np.array(rows, dtype=np.float64)


def film_z(pres: Prescription) -> float:
    """z of the film plane: last vertex + last thickness."""
    return float(pres.vertex_z[-1] + pres.surfaces[-1].thickness_mm)


def trace(pres: Prescription, origins: np.ndarray, directions: np.ndarray,
          wavelength_nm: float = LAMBDA_D_NM, clip: bool = True, stop_radius_mm: float | None = None,
          z_film: float | None = None) -> TraceResult:
    """Trace rays (object space is air) through every surface to the film plane.

    ``origins`` (N, 3) must lie before the first surface; ``directions`` (N, 3) need not be unit.
    ``clip=False`` ignores all semi-diameters (used to find chief rays); ``stop_radius_mm``
    stops the iris down; ``z_film`` overrides the film plane.
    """
    table = surface_table(pres, wavelength_nm, clip, stop_radius_mm)
    zf = film_z(pres) if z_film is None else float(z_film)
    return trace_table(table, np.asarray(origins, np.float64), np.asarray(directions, np.float64), zf)


def trace_table(table: np.ndarray, origins: np.ndarray, directions: np.ndarray, z_film: float) -> TraceResult:
    """The trace loop over a :func:`surface_table` (the numpy oracle of ``lens_trace.cl``)."""
    o = np.array(origins, dtype=np.float64, copy=True).reshape(-1, 3)
    d = np.array(directions, dtype=np.float64, copy=True).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n_rays = o.shape[0]
    status = np.zeros(n_rays, np.int8)
    where = np.full(n_rays, -1, np.int16)
    stop_xy = np.zeros((n_rays, 2))
    n_prev = 1.0
    with np.errstate(invalid="ignore", divide="ignore"):
        for k, (zk, c, sd, n_next, is_stop) in enumerate(table):
            alive = status == OK
            p = o - np.array([0.0, 0.0, zk])
            b = c * np.einsum("ij,ij->i", p, d) - d[:, 2]
            cc = c * np.einsum("ij,ij->i", p, p) - 2.0 * p[:, 2]
            disc = b * b - c * cc
            sq = np.sqrt(np.maximum(disc, 0.0))
            # Two algebraically equal forms of the vertex-side root; pick the one without
            # cancellation (the first is exact for planes, the second for rays far behind).
            t = np.where(-b > 0, cc / (-b + sq), (-b - sq) / c)
            miss = alive & ((disc < 0) | ~np.isfinite(t))
            status[miss] = MISS
            where[miss] = k
            alive &= ~miss
            q = p + t[:, None] * d
            h2 = q[:, 0] ** 2 + q[:, 1] ** 2
            out = alive & (h2 > sd * sd)
            status[out] = STOP if is_stop else CLIPPED
            where[out] = k
            if is_stop:
                stop_xy[alive] = q[alive, :2]
            alive &= ~out
            new_o = q + np.array([0.0, 0.0, zk])
            if n_next != n_prev or c != 0.0:
                nrm = np.stack([c * q[:, 0], c * q[:, 1], c * q[:, 2] - 1.0], axis=1)
                nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
                mu = n_prev / n_next
                cosi = -np.einsum("ij,ij->i", d, nrm)
                kk = 1.0 - mu * mu * (1.0 - cosi * cosi)
                tir = alive & (kk < 0)
                status[tir] = TIR
                where[tir] = k
                alive &= ~tir
                new_d = mu * d + (mu * cosi - np.sqrt(np.maximum(kk, 0.0)))[:, None] * nrm
            else:
                new_d = d
            o[alive] = new_o[alive]
            d[alive] = new_d[alive]
            n_prev = n_next
        alive = status == OK
        t = (z_film - o[:, 2]) / d[:, 2]
        back = alive & ~(d[:, 2] > 0)
        status[back] = MISS
        where[back] = len(table)
        alive &= ~back
        o[alive] = o[alive] + t[alive, None] * d[alive]
    return TraceResult(o, d, status, where, stop_xy)
