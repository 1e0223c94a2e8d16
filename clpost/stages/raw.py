r"""raw: a colour-filter-array sensor's raw recording, with a calibrated noise model.

Each photosite at column x, row y sits under one filter of the 2×2 pattern (RGGB, BGGR, GRBG,
GBRG or RCCB; C is clear) and records one value. Its channel's response to the working space's
linear RGB is a row of :math:`M` (:meth:`clpost.sensor_calibration.SensorCalibration.rgb_to_camera`:
the camera's XYZ→raw matrix times RGB→XYZ; its row sums are the per-channel gains, a clear
photosite's row is the sum of the three). The noise model is Wei et al. 2020 ("A Physics-based
Noise Formation Model for Extreme Low-light Raw Denoising", CVPR — "ELD") with the fixed-pattern
terms of EMVA 1288 (DSNU, PRNU), in electrons e⁻ and digital numbers DN:

.. math::

    \bar e = \max(M_{c(x,y)}\cdot\mathbf{rgb},\,0)\;e_{sat}\;(1 + \sigma_{PRNU}\,n_{PRNU}(x,y)),
    \qquad e_{sat} = \frac{W - B}{K}

.. math::

    D = \mathrm{clamp}\Big(\mathrm{round}\big(B + K\min(\mathrm{Poisson}(\bar e),\,FW)
        + \sigma_{DSNU}\,n_{DSNU}(x,y) + \sigma_{read}\,n + \sigma_{row}\,n_{row}(y)
        + \sigma_{col}\,n_{col}(x)\big),\ 0,\ W\Big)

.. math::

    \text{out} = \frac{D - B}{W - B}

K the system gain (DN/e⁻) at the camera's ISO, B and W the black and white levels, FW the full
well; every n is a standard normal: per photosite and frame (read), per row and frame (row noise,
ELD's :math:`N_r`), per column and frame (column noise), per photosite and fixed over frames (DSNU,
PRNU: the same every frame for one ``noise_seed``). Shot noise is ``rnd_poisson``
(``kernels/random.cl``: exact Poisson by inversion up to 32 e⁻, the normal approximation above);
means above 2·FW are capped there. Rounding to integer DN is the quantisation noise (ELD's
:math:`N_q`). Signal 1.0 (ISO 12232 saturation, the exposure stage's scale) of the most sensitive
channel reaches the white level. ELD's Tukey-λ read-noise shape is not modelled (Gaussian read
noise); a read noise whose tail matters needs it.

The noise parameters come from a per-ISO calibration file (:mod:`clpost.sensor_calibration`,
``docs/raw_isp.md``), interpolated log–log between its ISOs. The output is the black-subtracted
raw normalised so that 1.0 is the white level, the same value in all three channels (a
monochrome mosaic; slightly negative values below black are kept, as raw files keep them). The
pattern starts at the display window's top-left photosite (overscan continues it);
:mod:`clpost.raw_io` writes it as 16-bit DN with a sidecar, the ``isp`` stage develops it.

Randomness: counter-based hash (``kernels/random.cl``) of (``noise_seed``, frame index, pixel
index, 0–3) per photosite, (…, row, 8–9) and (…, column, 10–11) per frame, and (``noise_seed``,
:data:`FIXED_FRAME`, pixel index, 12–15) for the fixed pattern; :mod:`clpost.random` reproduces
it bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import random as rnd
from .. import sensor_calibration as calib
from ..errors import InputError
from ..params import one_of, param, show_none
from .base import PointwiseStage, per_camera
from .sensor import frame_index

FIXED_FRAME = 0xFFFFFFFF
"""The frame counter of the fixed-pattern noise (DSNU, PRNU): one pattern for every frame."""
CHANNELS = "RGBC"


def _check_calibration(name, value):
    if value is None:
        return None
    if not isinstance(value, str) or not value:
        raise InputError(f"Camera.{name}={value!r} must be a calibration file or a built-in sensor name "
                         f"({', '.join(calib.builtin_names())})")
    calib.load(value)  # names the file and the problem
    return value


@dataclass(frozen=True)
class RawParams:
    """raw: a colour-filter-array sensor from a per-ISO calibration file."""

    raw_calibration: str | None = param(
        None, unit="file", flag="--raw-calibration", check=_check_calibration, header="clpost.rawCalibration",
        show=show_none, scalar=False,
        help="raw sensor: a calibration JSON (docs/raw_isp.md) or built-in name (a7s2-like); records a CFA mosaic")
    cfa_pattern: str | None = param(
        None, unit="pattern", flag="--cfa", check=one_of(*calib.CFA_PATTERNS, optional=True),
        header="clpost.cfaPattern", show=show_none, scalar=False,
        help=f"colour filter array ({', '.join(calib.CFA_PATTERNS)}; default: the calibration's)")

    @staticmethod
    def check_options(camera, given):
        # a silently idle option is worse than an error (a library Camera(cfa_pattern=...) alone is unused)
        if camera.raw_calibration is None and camera.cfa_pattern is not None:
            raise InputError(f"--cfa {camera.cfa_pattern} needs a raw sensor: give --raw-calibration (e.g. "
                             "a7s2-like) or leave --cfa out")

    @staticmethod
    def validate(camera, inputs):
        if camera.raw_calibration is None:
            return
        for other, flag in (("film", "--film"), ("sensor_preset", "--sensor-preset")):
            if getattr(camera, other, None) is not None:
                raise InputError(f"Camera: raw_calibration={camera.raw_calibration!r} and {other}="
                                 f"{getattr(camera, other)!r} are both set; a camera records on one medium — "
                                 f"give --raw-calibration or {flag}, not both")
        calib.load(camera.raw_calibration).at_iso(camera.iso)  # an ISO outside the table is named now


def pattern(camera) -> str:
    return camera.cfa_pattern or calib.load(camera.raw_calibration).cfa_pattern


def cfa_phase(frame) -> tuple[int, int]:
    """(x, y) parity of the display window's top-left in the arrays: the pattern starts there (the
    sensor is the display window; overscan is recorded in the pattern's continuation)."""
    ox, oy = frame.windows.display_offset
    return ox % 2, oy % 2


def cfa_channels(pat: str) -> np.ndarray:
    """(2, 2) channel index (0 R, 1 G, 2 B, 3 C) of the photosites at (y mod 2, x mod 2)."""
    return np.array([CHANNELS.index(ch) for ch in pat]).reshape(2, 2)


def camera_matrix(camera) -> np.ndarray:
    """(4, 3): raw R, G, B and clear response to working-space RGB (clear = R + G + B rows)."""
    m = calib.load(camera.raw_calibration).rgb_to_camera(camera.working_space)
    return np.vstack([m, m.sum(axis=0, keepdims=True)])


class Raw(PointwiseStage):
    name = "raw"
    order = 85.5
    role = "a colour-filter-array sensor: one filter per photosite, calibrated shot/read/row/column/fixed-pattern noise"
    domains = ("signal", "raw")
    requires = ("exposure",)
    params = RawParams
    example = {"raw_calibration": "a7s2-like", "iso": 800}
    args = (("float", "e_sat"), ("float", "full_well"), ("float", "gain"), ("float", "read_noise"),
            ("float", "row_noise"), ("float", "col_noise"), ("float", "dsnu"), ("float", "prnu"),
            ("float", "black"), ("float", "white"), ("__global const float *", "matrix"),
            ("uint", "phase_x"), ("uint", "phase_y"), ("uint", "seed"), ("uint", "frame"))

    def skip_reason(self, camera, frame):
        return None if camera.raw_calibration else "no raw sensor (Camera.raw_calibration is None)"

    def reason_needed(self, camera, frame):
        c, n = calib.load(camera.raw_calibration), self._noise(camera)
        return (f"{c.name} {pattern(camera)}: ISO {camera.iso:g}, K {n.gain_dn_per_e:.4g} DN/e⁻, read "
                f"{n.read_noise_dn:.3g} DN, row {n.row_noise_dn:.3g}, column {n.column_noise_dn:.3g}, DSNU "
                f"{n.dsnu_dn:.3g} DN, PRNU {100 * n.prnu:.2g} %, {c.bits} bit, black {c.black_level_dn}, "
                f"white {c.white_level_dn}")

    def _noise(self, camera):
        return calib.load(camera.raw_calibration).at_iso(camera.iso)

    def defines(self, camera):
        ch = cfa_channels(pattern(camera))
        return {"RAW_CFA_00": int(ch[0, 0]), "RAW_CFA_01": int(ch[0, 1]), "RAW_CFA_10": int(ch[1, 0]),
                "RAW_CFA_11": int(ch[1, 1])}

    def replay_key(self, camera, frame):
        return (super().replay_key(camera, frame), frame_index(frame))  # the noise hash's frame counter

    @per_camera
    def _scalars(self, camera):
        c, n = calib.load(camera.raw_calibration), self._noise(camera)
        black, white = float(c.black_level_dn), float(c.white_level_dn)
        return c, n, (white - black) / n.gain_dn_per_e, black, white

    def values(self, camera, frame):
        c, n, e_sat, black, white = self._scalars(camera)
        f32 = np.float32
        return (f32(e_sat), f32(c.full_well_e), f32(n.gain_dn_per_e), f32(n.read_noise_dn), f32(n.row_noise_dn),
                f32(n.column_noise_dn), f32(n.dsnu_dn), f32(n.prnu), f32(black), f32(white),
                self._matrix(camera), *map(np.uint32, cfa_phase(frame)), np.uint32(camera.noise_seed),
                np.uint32(frame_index(frame)))

    @per_camera
    def _matrix(self, camera):
        return camera_matrix(camera).astype(np.float32).ravel()  # rows R, G, B, C (read-only: uploaded once)

    def reference(self, camera, frame, color):
        c, n, e_sat, black, white = self._scalars(camera)
        h, w, _ = color.shape
        y, x = np.mgrid[0:h, 0:w].astype(np.uint32)
        i = y * np.uint32(w) + x
        seed, fr = camera.noise_seed, frame_index(frame)
        px, py = cfa_phase(frame)
        ch = cfa_channels(pattern(camera))[(y + py) % 2, (x + px) % 2]
        s = np.einsum("hwk,hwk->hw", camera_matrix(camera)[ch], np.asarray(color, np.float64)[..., :3])

        def normal(f, a, b):
            return rnd.normal(rnd.hash4(seed, f, a, b), rnd.hash4(seed, f, a, b + 1))

        n_prnu = normal(FIXED_FRAME, i, 14)
        mean = np.maximum(np.maximum(s, 0.0) * e_sat * (1.0 + n.prnu * n_prnu), 0.0)
        mean = np.minimum(mean, 2.0 * c.full_well_e)
        h3 = rnd.hash4(seed, fr, i, 3)
        e = rnd.poisson(mean, rnd.uniform(rnd.hash4(seed, fr, i, 0)), normal(fr, i, 1))
        dn = (black + n.gain_dn_per_e * np.minimum(e, c.full_well_e) + n.dsnu_dn * normal(FIXED_FRAME, i, 12)
              + n.read_noise_dn * rnd.normal(h3, rnd.mix(h3 ^ np.uint32(0x5BD1E995)))
              + n.row_noise_dn * normal(fr, y, 8) + n.column_noise_dn * normal(fr, x, 10))
        out = (np.clip(np.round(dn), 0.0, white) - black) / (white - black)
        return np.repeat(out[..., None], 3, axis=2)
