r"""white_balance: the camera's white balance — neutral for light of a chosen colour temperature.

A camera set to colour temperature :math:`T` renders a neutral surface lit by a blackbody of
temperature :math:`T` as neutral. A render's scene white is its working space's white point
:math:`W` (D65 for Rec. 709, ≈ D60 for ACEScg), so the camera sees every pixel as if the light were
:math:`T`'s and adapts it to :math:`W` (von Kries, CAT02):

.. math::

    \mathbf{c}' = M_{XYZ\to RGB}\; M_{CAT02}^{-1}\,
        \mathrm{diag}\!\left(\frac{\rho_W}{\rho_T}\right) M_{CAT02}\; M_{RGB\to XYZ}\;\mathbf{c}

(:math:`M_{XYZ\to RGB}` the exact inverse of the working space's RGB→XYZ) with :math:`\rho` the CAT02 cone responses of the two whites (Y = 1). :math:`T`'s chromaticity is
the Planckian locus of Kang et al. 2002 (valid 1667–25000 K). So a tungsten setting (3200 K) in
daylight renders blue, a daylight setting under tungsten orange — as a camera does; applied as
a correction filter before the sensor (linear, so it commutes with the blurs and the exposure).
Sources: CIE 159:2004 (CAT02); Kang, B. et al., J. Korean Phys. Soc. 41 (2002) 865–871; the
matrices from colour-science (``colour.adaptation.matrix_chromatic_adaptation_VonKries``,
``colour.temperature.CCT_to_xy_Kang2002``). Tint (the green–magenta offset from the locus) is not
modelled.

Domain/range: any finite RGB → RGB (a 3 × 3 matrix per pixel; negative results are possible for
saturated colours outside the adapted gamut, as in any chromatic adaptation).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import InputError
from ..params import finite_value, param, parse_fraction
from .base import PointwiseStage

T_RANGE_K = (1667.0, 25000.0)
"""Where Kang et al.'s Planckian-locus approximation holds."""


def _check_temperature(name, value):
    if value is None:
        return None
    t = finite_value(name, value, "K", "e.g. 3200 (tungsten) or 5500 (daylight)")
    if not T_RANGE_K[0] <= t <= T_RANGE_K[1]:
        raise InputError(f"Camera.{name}={t:g} K is outside {T_RANGE_K[0]:g}–{T_RANGE_K[1]:g} K (the Planckian "
                         "locus model's range); e.g. 3200 (tungsten) or 5500 (daylight)")
    return t


@dataclass(frozen=True)
class WhiteBalanceParams:
    """The camera's white-balance setting."""

    white_balance_k: float | None = param(
        None, unit="K", flag="--white-balance", parse=parse_fraction, check=_check_temperature,
        header="clpost.whiteBalance_K", show=lambda v: None if v is None else f"{v:g}", scalar=True,
        help="camera white balance: colour temperature in K rendered neutral (3200 tungsten, 5500 daylight); "
             "default: the render's own white")


@lru_cache(maxsize=64)
def white_balance_matrix(t_k: float, working_space: str) -> np.ndarray:
    """The 3 × 3 matrix of the module docstring (float64, rows: output R, G, B)."""
    import colour

    from ..colorspace import WORKING_SPACES

    space = colour.RGB_COLOURSPACES[WORKING_SPACES[working_space]]
    xyz_t = colour.xy_to_XYZ(colour.temperature.CCT_to_xy_Kang2002(t_k))
    xyz_w = colour.xy_to_XYZ(space.whitepoint)
    cat = colour.adaptation.matrix_chromatic_adaptation_VonKries(xyz_t, xyz_w, transform="CAT02")
    to_xyz = np.asarray(space.matrix_RGB_to_XYZ, np.float64)
    # the exact inverse, not the colourspace's published (rounded: sRGB's 4 digits) XYZ→RGB, so
    # the working white maps to itself exactly
    m = np.linalg.inv(to_xyz) @ cat @ to_xyz
    m.setflags(write=False)
    return m


class WhiteBalance(PointwiseStage):
    name = "white_balance"
    order = 65.0
    role = "the camera's white balance as a correction filter on the sensor's light"
    domains = ("image", "image")
    params = WhiteBalanceParams
    example = {"white_balance_k": 3200.0}
    args = tuple(("float", f"m{i}{j}") for i in range(3) for j in range(3))

    def skip_reason(self, camera, frame):
        if camera.white_balance_k is None:
            return "no white balance set (Camera.white_balance_k is None: the render's white stays white)"
        return None

    def reason_needed(self, camera, frame):
        return f"neutral at {camera.white_balance_k:g} K (CAT02 to the {camera.working_space} white)"

    def values(self, camera, frame):
        m = white_balance_matrix(float(camera.white_balance_k), camera.working_space)
        return tuple(np.float32(v) for v in m.ravel())

    def reference(self, camera, frame, color):
        m = white_balance_matrix(float(camera.white_balance_k), camera.working_space)
        return np.asarray(color, np.float64) @ m.T
