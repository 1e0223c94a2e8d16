r"""Cubemap renders for fields of view a pinhole render cannot cover (beyond 150°; see
:data:`clpost.calibration.frustum.PINHOLE_LIMIT_DEG`).

A cubemap is six pinhole renders from the camera's centre, 90° each, looking along ±x, ±y, ±z of
the camera frame (x right, y down, z forward). clpost stores it as one image, an **atlas** of the
six faces side by side in the order of :data:`FACES`, each :math:`S = N + 2p` pixels square: N
pixels span the face's 90° exactly (focal length :math:`f = N/2`, principal point
:math:`c = (S - 1)/2`) and p = :data:`PAD` pixels beyond it on every side, so the stage's 4 × 4
B-spline taps never straddle two faces. A ray p (camera frame) is looked up on the face whose
forward axis is nearest to it (largest :math:`\mathbf f_i\cdot\mathbf p`), at

.. math::

    q = R_i^\top p, \qquad s_x = iS + f\,q_x/q_z + c, \qquad s_y = f\,q_y/q_z + c

with :math:`R_i = [\mathbf r_i\ \mathbf d_i\ \mathbf f_i]` the face's right, down and forward axes
in camera coordinates (right = down × forward: every face is a right-handed camera like the
camera itself). A renderer renders face i as a pinhole camera rotated by :math:`R_i`
(:meth:`clpost.render.PyVistaRenderer.render_cubemap`) and records ``metadata["cubemap"] = (N, p)``;
the distortion stage then samples the atlas through the model's exact ``unproject``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

PAD = 4
"""Pixels around each face beyond its 90°: the B-spline window reaches 2 px past a position."""

FACES = (
    # name, forward, down (right = down × forward)
    ("+x", (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    ("-x", (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    ("+y", (0.0, 1.0, 0.0), (0.0, 0.0, -1.0)),
    ("-y", (0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    ("+z", (0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    ("-z", (0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
)
"""The six faces in atlas order."""


def face_rotation(i: int) -> np.ndarray:
    """:math:`R_i = [\\mathbf r\\ \\mathbf d\\ \\mathbf f]` (columns in camera coordinates) of face i."""
    _, f, d = FACES[i]
    f, d = np.array(f), np.array(d)
    return np.stack([np.cross(d, f), d, f], axis=1)


_ROT = np.stack([face_rotation(i) for i in range(6)])


@dataclass(frozen=True)
class CubemapSpec:
    """A cubemap atlas of six faces of ``face`` pixels (90° each) plus ``pad`` on every side."""

    face: int
    pad: int = PAD

    @property
    def size(self) -> int:
        """S: one face's side in the atlas, padding included."""
        return self.face + 2 * self.pad

    @property
    def width(self) -> int:
        return 6 * self.size

    @property
    def height(self) -> int:
        return self.size

    def intrinsics(self) -> tuple[float, float, float, float]:
        """(f, f, c, c) of every face's S × S pinhole render."""
        c = (self.size - 1) / 2
        return self.face / 2, self.face / 2, c, c

    def positions(self, x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rays (camera frame) → atlas positions (s_x, s_y) (module docstring)."""
        p = np.stack([np.asarray(x, np.float64), np.asarray(y, np.float64), np.asarray(z, np.float64)], -1)
        fwd = _ROT[:, :, 2]  # (6, 3)
        i = np.argmax(p @ fwd.T, axis=-1)
        q = np.einsum("...k,...kj->...j", p, _ROT[i])  # Rᵢᵀ p
        f, _, c, _ = self.intrinsics()
        return i * self.size + f * q[..., 0] / q[..., 2] + c, f * q[..., 1] / q[..., 2] + c


def required_cubemap(model) -> CubemapSpec:
    """The cubemap for ``model``: faces whose centre has the model's larger focal length
    (N = 2⌈max(f_x, f_y)⌉ px, so f = N/2 ≥ f_x, f_y px per radian at the face centre)."""
    return CubemapSpec(2 * int(math.ceil(max(model.fx, model.fy))))
