r"""The distortion model as one EXR header string with named fields (``clpost.distortion``).

Written::

    model=opencv width=1920 height=1080 fx=1800 fy=1800 cx=959.5 cy=539.5 k1=-0.12 k2=0.03 p1=0 p2=0 k3=0

— ``model`` (``opencv`` or ``fisheye``), the image size, K in pixels (OpenCV's pixel-centre
convention) and the family's coefficients: the standard model's k1, k2, p1, p2, k3 always and any
other non-zero one (k4…k6, s1…s4, tau_x, tau_y) by name; the fisheye model's k1…k4. Numbers are
exact (:func:`clpost.params.exact_g`), so ``--camera-from`` reads back the same model. The
bare list the header held before (``W H fx fy cx cy`` and the 14-entry OpenCV vector) is still
read.
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..params import exact_g
from .model import COEFF_NAMES, OpenCVModel

_ALWAYS = ("k1", "k2", "p1", "p2", "k3")


def header_text(m: OpenCVModel) -> str:
    """``model=… width=… height=… fx=… fy=… cx=… cy=… k1=…`` (module docstring)."""
    names = m.coeff_names if m.distortion_model != "opencv" else [n for n in COEFF_NAMES if n in _ALWAYS or getattr(m, n)]
    fields = [("width", m.width), ("height", m.height), ("fx", m.fx), ("fy", m.fy), ("cx", m.cx), ("cy", m.cy)]
    fields += [(n, getattr(m, n)) for n in names]
    return " ".join([f"model={m.distortion_model}"] + [f"{k}={exact_g(float(v))}" for k, v in fields])


def model_from_header(text: str, source: str = "header") -> OpenCVModel:
    """:func:`header_text`'s string (or the older bare list) → the model."""
    tokens = text.split()
    if tokens and all("=" not in t for t in tokens):  # the bare list of older outputs
        t = [float(x) for x in tokens]
        if len(t) < 10:
            raise InputError(f"{source}: clpost.distortion {text!r} has {len(t)} numbers; expected W H fx fy cx cy "
                             "and 4 to 14 coefficients")
        k = np.array([[t[2], 0, t[4]], [0, t[3], t[5]], [0, 0, 1]])
        return OpenCVModel.from_vector(int(t[0]), int(t[1]), k, t[6:], source=source)
    d = {}
    for tok in tokens:
        key, sep, val = tok.partition("=")
        if not sep or key in d:
            raise InputError(f"{source}: clpost.distortion field {tok!r} is not name=value (or given twice)")
        d[key] = val
    family = d.pop("model", "opencv")
    allowed = {"width", "height", "fx", "fy", "cx", "cy", *COEFF_NAMES, "xi", "alpha", "omega"}
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise InputError(f"{source}: clpost.distortion has unknown fields {', '.join(unknown)}")
    missing = [k for k in ("width", "height", "fx", "fy", "cx", "cy") if k not in d]
    if missing:
        raise InputError(f"{source}: clpost.distortion lacks {', '.join(missing)}")
    try:
        vals = {k: (int(v) if k in ("width", "height") else float(v)) for k, v in d.items()}
    except ValueError as exc:
        raise InputError(f"{source}: clpost.distortion has a field that is not a number ({exc})") from None
    return OpenCVModel(distortion_model=family, source=source, **vals)
