r"""A raw sensor's calibration: its per-ISO noise parameters, levels and colour response, read from
a JSON file (format ``clpost-sensor-calibration/1``, documented in ``docs/raw_isp.md``).

Noise parameters are tabulated at the ISOs a calibration measured; between two of them each
parameter p is interpolated linearly in log–log (Wei et al. 2020, "A Physics-based Noise
Formation Model for Extreme Low-light Raw Denoising", CVPR, Sec. 4: log K is linear in log ISO
and the log noise scales are linear in log K):

.. math::

    \log p(S) = (1-t)\,\log p(S_i) + t\,\log p(S_{i+1}),\qquad
    t = \frac{\log S - \log S_i}{\log S_{i+1} - \log S_i}

(a parameter that is 0 at either end is interpolated linearly instead). An ISO outside the table
is refused — the file says what was measured.

Colour: ``xyz_to_camera`` is the camera's XYZ(D65) → raw matrix as Adobe's DNG ColorMatrix and
dcraw's ``adobe_coeff`` table give it. The raw response to the working space's linear RGB is
:math:`M = M_{XYZ\to cam}\,M_{709\to XYZ}\,M_{RGB\to 709}` scaled so that the largest row sum is
1: a white of signal 1 fills the most sensitive channel (green) exactly; the row sums are the
per-channel gains, so a grey's raw values are ``M @ (1, 1, 1)`` (dcraw ``pre_mul`` = their
reciprocals). :math:`M_{RGB\to 709}` (Bradford-adapted; identity for Rec. 709) takes the working
space's white to D65, the white of the camera matrix: a render's scene white is its working space's
white (as the ``white_balance`` stage assumes), so it records as the camera's daylight neutral.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from .errors import InputError

FORMAT = "clpost-sensor-calibration/1"
CFA_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG", "RCCB")
"""2×2 colour filter arrays, read row by row from the top-left photosite (C: clear, no filter)."""
NOISE_KEYS = ("gain_dn_per_e", "read_noise_dn", "row_noise_dn", "column_noise_dn", "dsnu_dn", "prnu")
def builtin_dir() -> Path:
    """``lens_data/sensors`` (:func:`clpost.optics.prescription.lens_data_dir` finds lens_data)."""
    from .optics.prescription import lens_data_dir

    return lens_data_dir() / "sensors"


def builtin_names() -> list[str]:
    return sorted(p.stem for p in builtin_dir().glob("*.json"))


@dataclass(frozen=True)
class NoiseAtIso:
    """One ISO's parameters (interpolated): DN are the raw file's digital numbers."""
    iso: float
    gain_dn_per_e: float
    read_noise_dn: float
    row_noise_dn: float
    column_noise_dn: float
    dsnu_dn: float
    prnu: float


@dataclass(frozen=True)
class SensorCalibration:
    name: str
    path: str
    bits: int
    black_level_dn: int
    white_level_dn: int
    full_well_e: float
    cfa_pattern: str
    xyz_to_camera: tuple
    table: tuple  # NoiseAtIso, ascending ISO

    def at_iso(self, iso: float) -> NoiseAtIso:
        isos = [t.iso for t in self.table]
        if not isos[0] <= iso <= isos[-1]:
            raise InputError(f"Camera.iso={iso:g} is outside the sensor calibration {self.path} (ISO {isos[0]:g}–"
                             f"{isos[-1]:g}); choose an ISO in that range or add a measurement to the file")
        if iso in isos:
            return self.table[isos.index(iso)]
        i = int(np.searchsorted(isos, iso, side="right")) - 1
        a, b = self.table[i], self.table[i + 1]
        t = (np.log(iso) - np.log(a.iso)) / (np.log(b.iso) - np.log(a.iso))
        vals = {}
        for k in NOISE_KEYS:
            pa, pb = getattr(a, k), getattr(b, k)
            vals[k] = float(np.exp((1 - t) * np.log(pa) + t * np.log(pb)) if pa > 0 and pb > 0
                            else (1 - t) * pa + t * pb)
        return NoiseAtIso(iso=float(iso), **vals)

    def rgb_to_camera(self, working_space: str = "rec709") -> np.ndarray:
        """(3, 3) working-space linear RGB → raw R, G, B response (module docstring)."""
        import colour

        from .colorspace import WORKING_SPACES

        rec709 = colour.RGB_COLOURSPACES["ITU-R BT.709"]
        m = np.asarray(self.xyz_to_camera, np.float64) @ np.asarray(rec709.matrix_RGB_to_XYZ, np.float64)
        m = m / m.sum(axis=1).max()
        if working_space == "rec709":
            return m
        to709 = colour.matrix_RGB_to_RGB(colour.RGB_COLOURSPACES[WORKING_SPACES[working_space]], rec709,
                                         chromatic_adaptation_transform="Bradford")
        return m @ np.asarray(to709, np.float64)


def _fail(path, what):
    return InputError(f"{path}: {what}; see docs/raw_isp.md for the calibration file format "
                      f"(an example: {builtin_dir() / 'a7s2-like.json'})")


def resolve(name_or_path: str) -> Path:
    """A built-in calibration's name (``lens_data/sensors/<name>.json``) or a file path."""
    p = builtin_dir() / f"{name_or_path}.json"
    if "/" not in name_or_path and not name_or_path.endswith(".json") and p.is_file():
        return p
    q = Path(name_or_path)
    if not q.is_file():
        raise InputError(f"Camera.raw_calibration={name_or_path!r}: no such file and not a built-in sensor "
                         f"({', '.join(builtin_names())}); give a calibration JSON (docs/raw_isp.md)")
    return q


@lru_cache(maxsize=16)
def load(name_or_path: str) -> SensorCalibration:
    """Read and check a calibration (cached per name)."""
    path = resolve(name_or_path)
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise _fail(path, f"not readable JSON ({e})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise _fail(path, f"'format' must be {FORMAT!r}")

    def num(d, k, lo=None, integer=False):
        v = d.get(k) if isinstance(d, dict) else None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or (integer and int(v) != v):
            raise _fail(path, f"{k!r} must be a finite {'integer' if integer else 'number'} (got {v!r})")
        if lo is not None and v < lo:
            raise _fail(path, f"{k!r}={v!r} must be >= {lo}")
        return int(v) if integer else float(v)

    bits = num(doc, "bits", 1, True)
    if bits > 16:
        raise _fail(path, f"'bits'={bits} must be <= 16 (raw output is 16-bit)")
    black, white = num(doc, "black_level_dn", 0, True), num(doc, "white_level_dn", 1, True)
    if not black < white <= (1 << bits) - 1:
        raise _fail(path, f"levels must satisfy 0 <= black_level_dn < white_level_dn <= 2^bits - 1 "
                          f"(got {black}, {white}, bits {bits})")
    cfa = doc.get("cfa_pattern")
    if cfa not in CFA_PATTERNS:
        raise _fail(path, f"'cfa_pattern'={cfa!r} must be one of {', '.join(CFA_PATTERNS)}")
    try:
        m = np.asarray(doc.get("xyz_to_camera"), np.float64)
        ok = m.shape == (3, 3) and np.isfinite(m).all() and abs(np.linalg.det(m)) > 1e-9
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise _fail(path, "'xyz_to_camera' must be an invertible 3x3 matrix of numbers (rows: camera R, G, B)")
    rows = doc.get("iso")
    if not isinstance(rows, list) or not rows:
        raise _fail(path, "'iso' must be a non-empty list of per-ISO entries")
    table = []
    for r in rows:
        vals = {k: num(r, k, 0.0) for k in NOISE_KEYS}
        iso = num(r, "iso", 1e-6)
        if vals["gain_dn_per_e"] <= 0:
            raise _fail(path, f"ISO {iso:g}: 'gain_dn_per_e' must be > 0")
        table.append(NoiseAtIso(iso=iso, **vals))
    table.sort(key=lambda t: t.iso)
    if len({t.iso for t in table}) != len(table):
        raise _fail(path, "an ISO is listed twice in 'iso'")
    return SensorCalibration(name=str(doc.get("name", path.stem)), path=str(path), bits=bits, black_level_dn=black,
                             white_level_dn=white, full_well_e=num(doc, "full_well_e", 1.0), cfa_pattern=cfa,
                             xyz_to_camera=tuple(map(tuple, m.tolist())), table=tuple(table))
