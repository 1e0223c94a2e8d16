r"""isp: a reference camera image signal processor that develops the ``raw`` stage's mosaic into
a display-encoded sRGB image ("camera-JPEG-like"): demosaic, white balance, colour matrix, tone
curve, sRGB encoding. :mod:`clpost.raw_io` writes the result as an 8-bit JPEG at
``isp_jpeg_quality``.

1. **Demosaic**, Malvar, He & Cutler 2004 ("High-quality linear interpolation for demosaicing of
   Bayer-patterned color images", ICASSP): each missing value is a 5×5 linear filter of the
   mosaic — bilinear interpolation corrected by the Laplacian of the photosite's own channel
   (weights /8, :data:`MHC_FILTERS`): G at R/B sites ``G_AT_RB``; R (B) at a G site in a red
   (blue) row ``RB_AT_G_ROW``, in a red (blue) column ``RB_AT_G_COL``; B at R and R at B
   ``RB_AT_BR``. Borders mirror the mosaic about the edge photosite (numpy's ``reflect``, scipy's
   ``mirror``), which keeps the pattern's parity. The oracle is ``colour_demosaicing.
   demosaicing_CFA_Bayer_Malvar2004``; it extends the border by repeating the edge photosite
   (scipy's default ``reflect``), which puts the wrong colour into the 2-photosite rim, so the
   tests give it the mosaic mirrored by 2 photosites and compare the inside — equal everywhere.
   RCCB is demosaiced as RGGB with C in G's place.
2. **White balance**: raw channel c times :math:`w_c = 1/\sum_k M_{ck}` (the calibration's
   response to a D65 white, :mod:`clpost.sensor_calibration`; G and C scaled alike): a neutral
   of the working space comes out neutral. Other illuminants: the ``white_balance`` stage before
   the sensor.
3. **Colour matrix** camera → linear sRGB: :math:`C = (\mathrm{diag}(w)\,M_{3})^{-1}` with
   :math:`M_3` the rows of the pattern's three channels (R, G or C, B) for Rec. 709 primaries; its
   rows sum to 1, so white stays white (dcraw's ``cam_rgb`` inverse).
4. **Tone curve** (``isp_tone_white`` :math:`L_w > 0`), extended Reinhard (Reinhard et al. 2002,
   "Photographic tone reproduction for digital images", eq. 4) per channel on the clipped-at-0
   value: :math:`y = x\,(1 + x/L_w^2)/(1 + x)` — :math:`y(L_w) = 1`; off (0): :math:`y = x`.
5. **sRGB encoding** (IEC 61966-2-1) of :math:`\mathrm{clamp}(y, 0, 1)`:
   :math:`12.92\,y` for :math:`y \le 0.0031308`, else :math:`1.055\,y^{1/2.4} - 0.055`.

Domain/range: the raw stage's normalised mosaic (channel 0) → display-encoded sRGB in [0, 1]
in all three channels. Frames must be at least 3×3 (the 5×5 filters' mirror).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..params import boolean, integer, param, parse_on_off, show_default
from .base import GatherStage, per_camera
from .raw import cfa_channels, cfa_phase, pattern

MHC_FILTERS = {
    "G_AT_RB": np.array([[0, 0, -1, 0, 0], [0, 0, 2, 0, 0], [-1, 2, 4, 2, -1], [0, 0, 2, 0, 0],
                         [0, 0, -1, 0, 0]]) / 8.0,
    "RB_AT_G_ROW": np.array([[0, 0, 0.5, 0, 0], [0, -1, 0, -1, 0], [-1, 4, 5, 4, -1], [0, -1, 0, -1, 0],
                             [0, 0, 0.5, 0, 0]]) / 8.0,
    "RB_AT_BR": np.array([[0, 0, -1.5, 0, 0], [0, 2, 0, 2, 0], [-1.5, 0, 6, 0, -1.5], [0, 2, 0, 2, 0],
                          [0, 0, -1.5, 0, 0]]) / 8.0,
}
MHC_FILTERS["RB_AT_G_COL"] = MHC_FILTERS["RB_AT_G_ROW"].T


def _check_tone(name, value):
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not np.isfinite(v) or not (v == 0.0 or v >= 1.0):
        raise InputError(f"Camera.{name}={value!r} must be 0 (no tone curve) or a white point >= 1 (signal "
                         "that maps to display white), e.g. 4")
    return v


@dataclass(frozen=True)
class IspParams:
    """isp: develop the raw stage's mosaic into a camera-JPEG-like image."""

    isp: bool = param(False, unit="on/off", flag="--isp", parse=parse_on_off, check=boolean, header="clpost.isp",
                      show=lambda v: "on" if v else None, scalar=False,
                      help="develop the raw mosaic (needs --raw-calibration): demosaic (Malvar-He-Cutler), white "
                           "balance, colour matrix, tone curve, sRGB; a .jpg/.png output gets it as is")
    isp_tone_white: float = param(0.0, unit="signal", flag="--isp-tone-white", parse=float, check=_check_tone,
                                  header="clpost.ispToneWhite", show=show_default, scalar=True,
                                  help="ISP tone curve: extended-Reinhard white point (0 = none, clip at 1)")
    isp_jpeg_quality: int = param(90, unit="quality", flag="--jpeg-quality", parse=int,
                                  check=integer(1, 101, rule="an integer from 1 to 100"),
                                  header="clpost.jpegQuality", show=show_default, scalar=True,
                                  help="JPEG quality of an ISP output written as .jpg (Pillow's scale, 1-100)")

    @staticmethod
    def check_options(camera, given):
        # a silently idle option is worse than an error (a library Camera(isp=True) alone is the identity)
        if camera.isp and camera.raw_calibration is None:
            raise InputError("--isp on needs a raw sensor to develop: give --raw-calibration (e.g. a7s2-like) or "
                             "leave --isp out")


def shifted_pattern(pat: str, x0: int, y0: int) -> str:
    """The 2×2 pattern seen from column ``x0``, row ``y0`` of a mosaic with pattern ``pat``."""
    return "".join(pat[((y0 + dy) % 2) * 2 + (x0 + dx) % 2] for dy in (0, 1) for dx in (0, 1))


def demosaic_pattern(pat: str) -> str:
    """The Bayer pattern the demosaic uses (RCCB → RGGB: clear photosites take green's place)."""
    return pat.replace("C", "G")


def _srgb_to_camera(camera) -> np.ndarray:
    """(3, 3) linear sRGB → the pattern's raw channels R, G|C, B (whatever the working space: the
    ISP develops to sRGB, balanced for its D65 white)."""
    from .. import sensor_calibration as calib

    m = calib.load(camera.raw_calibration).rgb_to_camera("rec709")
    return np.vstack([m, m.sum(axis=0, keepdims=True)])[[0, 3 if "C" in pattern(camera) else 1, 2]]


def white_balance_gains(camera) -> np.ndarray:
    """(3,) gains of the pattern's channels R, G|C, B: reciprocal row sums of their responses to D65 white."""
    return 1.0 / _srgb_to_camera(camera).sum(axis=1)


def colour_matrix(camera) -> np.ndarray:
    """(3, 3) white-balanced camera R, G|C, B → linear sRGB (Rec. 709): rows sum to 1."""
    m = _srgb_to_camera(camera)
    return np.linalg.inv(np.diag(1.0 / m.sum(axis=1)) @ m)


def mhc_demosaic(mosaic: np.ndarray, bayer: str) -> np.ndarray:
    """Malvar–He–Cutler demosaic of a (H, W) mosaic with Bayer pattern ``bayer`` → (H, W, 3), float64."""
    cfa = np.asarray(mosaic, np.float64)
    h, w = cfa.shape
    pad = np.pad(cfa, 2, mode="reflect")  # numpy's "reflect" = scipy's "mirror"

    def filt(k):
        out = np.zeros_like(cfa)
        for dy in range(5):
            for dx in range(5):
                if k[dy, dx]:
                    out += k[dy, dx] * pad[dy:dy + h, dx:dx + w]
        return out

    f = {name: filt(k) for name, k in MHC_FILTERS.items()}
    ch = cfa_channels(bayer)
    y, x = np.mgrid[0:h, 0:w]
    site = ch[y % 2, x % 2]  # 0 R, 1 G, 2 B
    red_row = (ch[y % 2] == 0).any(axis=-1)  # this row holds red photosites
    r = np.select([site == 0, site == 2, red_row], [cfa, f["RB_AT_BR"], f["RB_AT_G_ROW"]], f["RB_AT_G_COL"])
    b = np.select([site == 2, site == 0, red_row], [cfa, f["RB_AT_BR"], f["RB_AT_G_COL"]], f["RB_AT_G_ROW"])
    g = np.where(site == 1, cfa, f["G_AT_RB"])
    return np.stack([r, g, b], axis=-1)


def tone(x, white):
    """The tone curve (module docstring, 4) on x ≥ 0."""
    return x if white == 0 else x * (1.0 + x / (white * white)) / (1.0 + x)


def srgb_encode(y):
    y = np.clip(y, 0.0, 1.0)
    return np.where(y <= 0.0031308, 12.92 * y, 1.055 * np.power(y, 1.0 / 2.4) - 0.055)


def _check_size(frame):
    if frame.width < 3 or frame.height < 3:
        raise InputError(f"isp: the frame is {frame.width}x{frame.height}; the demosaic needs at least 3x3 "
                         "photosites — render larger or leave --isp out")


class Isp(GatherStage):
    name = "isp"
    order = 97.0
    role = "develops the recorded raw mosaic as a camera's processor does, after the sensor has recorded it"
    domains = ("raw", "print")
    requires = ("raw",)
    params = IspParams
    example = {"raw_calibration": "a7s2-like", "iso": 800, "isp": True, "isp_tone_white": 4.0}

    def skip_reason(self, camera, frame):
        if not camera.isp:
            return "no image processor (Camera.isp is off)"
        return None if camera.raw_calibration else "no raw mosaic to develop (Camera.raw_calibration is None)"

    def reason_needed(self, camera, frame):
        return (f"develops the {pattern(camera)} mosaic: MHC demosaic, white balance "
                f"{np.round(white_balance_gains(camera), 3).tolist()}, colour matrix, "
                f"{'tone white ' + format(camera.isp_tone_white, 'g') if camera.isp_tone_white else 'no tone curve'}, sRGB")

    @per_camera
    def _tables(self, camera):
        """(15,) float32: WB gains (3), colour matrix rows (9), pad (3)."""
        t = np.zeros(15, np.float32)
        t[:3] = white_balance_gains(camera)
        t[3:12] = colour_matrix(camera).ravel()
        return t

    def defines(self, camera):
        ch = cfa_channels(demosaic_pattern(pattern(camera)))
        return {"ISP_CFA_00": int(ch[0, 0]), "ISP_CFA_01": int(ch[0, 1]), "ISP_CFA_10": int(ch[1, 0]),
                "ISP_CFA_11": int(ch[1, 1])}

    def enqueue(self, rt, camera, frame, src, dst, aux):
        from ..codegen import library
        from ..runtime import kernel_source

        _check_size(frame)
        w, h = frame.width, frame.height
        knl = rt.kernel(library() + kernel_source("isp"), "isp", self.defines(camera))
        px, py = cfa_phase(frame)
        return [rt.launch(knl, (w, h), None, src, dst, np.int32(w), np.int32(h), np.int32(px), np.int32(py),
                          rt.constant(self._tables(camera)), np.float32(camera.isp_tone_white))]

    def reference(self, camera, frame, color):
        _check_size(frame)
        rgb = mhc_demosaic(np.asarray(color, np.float64)[..., 0],
                           shifted_pattern(demosaic_pattern(pattern(camera)), *cfa_phase(frame)))
        lin = (rgb * white_balance_gains(camera)) @ colour_matrix(camera).T
        return srgb_encode(tone(np.maximum(lin, 0.0), camera.isp_tone_white))
