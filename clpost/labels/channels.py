r"""Label channels: which ones a frame carries, and how the geometric stages move them.

**Which.** ``Camera.labels`` (``--labels``) names the input channels read into
:attr:`clpost.Frame.labels` besides colour, alpha, depth and velocity (which the layout reads):

=========  ===========================================================================================
``auto``   (default) the id / segmentation channels the file has: a channel is one when a
           component of its dot-separated name, lower-cased, is in :data:`AUTO_LAYERS` or starts
           with ``crypto`` (Cryptomatte) — e.g. ``ViewLayer.IndexOB.X``, ``id``, ``instance.R``,
           ``CryptoObject00.R``
``all``    every channel the layout does not read
``none``   no label channel
NAMES      comma-separated; a name takes the channels it equals or whose dot-separated name
           contains it as whole components (``Normal`` takes ``ViewLayer.Normal.X/Y/Z``, ``N``
           ``N.X/Y/Z``); a name that takes no channel is an error naming the file's channels
=========  ===========================================================================================

Depth is always carried (``Frame.depth``, nearest, +inf where there is no data).

**How.** The geometric stages (``distortion``; the focus-breathing rescale of the plate,
:mod:`clpost.breathing`) move every label plane by **nearest** sampling: output pixel p takes the
value of the source pixel :math:`\operatorname{rint}(s(p))` nearest to its source position s(p) —
one of the four pixels of the bilinear cell around s(p), so an id is never blended, averaged or
invented (ids, segmentation, Cryptomatte hashes and the three components of a normal all come from
one source pixel). Depth uses the same rule (nearest, not min: a silhouette keeps the depth of the
surface whose id it carries). Output pixels without a preimage (alpha 0) take :data:`LABEL_FILL`
(0, the usual background id). Lateral colour moves R and B about the d-line geometry of the render,
which labels keep (its G shift is a fraction of a pixel of a colour channel, not of the scene).

The device kernel (``kernels/distortion_labels.cl``) copies 32-bit words, so float, int32 and uint32
planes come out bit for bit; :func:`nearest_labels` is its numpy reference.
"""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..errors import InputError

AUTO_LAYERS = frozenset({
    "id", "ids", "objectid", "object_id", "materialid", "material_id", "instance", "instanceid", "instance_id",
    "indexob", "indexma", "segmentation", "semantic", "semantic_id", "class", "classid", "class_id", "label",
})
"""Lower-cased name components that make a channel an id channel under ``--labels auto`` (Blender's
``IndexOB``/``IndexMA`` passes, the usual names of instance/semantic id AOVs)."""

LABEL_FILL = 0
"""The label of output pixels without a preimage (alpha 0)."""

KEYWORDS = ("auto", "all", "none")


def parse_labels(text: str) -> str:
    """``--labels`` text → its normal form: ``auto``, ``all``, ``none`` or NAME[,NAME…]."""
    t = str(text).strip()
    if t.lower() in KEYWORDS:
        return t.lower()
    names = [n.strip() for n in t.split(",")]
    if not t or any(not n for n in names) or any(n.lower() in KEYWORDS for n in names):
        raise InputError(f"Camera.labels={text!r}: give auto, all, none or comma-separated channel names "
                         "(e.g. IndexOB,Normal or id)")
    return ",".join(names)


def check_labels(name: str, value) -> str:
    """The parameter's check (``clpost.params``): :func:`parse_labels`, naming the field."""
    if not isinstance(value, str):
        raise InputError(f"Camera.{name}={value!r} must be a str: auto, all, none or comma-separated channel names")
    return parse_labels(value)


def auto_label(channel: str) -> bool:
    """Whether ``--labels auto`` carries ``channel`` (module docstring)."""
    parts = [p.lower() for p in channel.split(".")]
    return any(p in AUTO_LAYERS or p.startswith("crypto") for p in parts)


def _takes(name: str, channel: str) -> bool:
    c, n = channel.split("."), name.split(".")
    return any(c[i:i + len(n)] == n for i in range(len(c) - len(n) + 1))


def select_labels(spec: str, channels: Iterable[str], where: str = "") -> list[str]:
    """The channels (of those the layout leaves, ``channels``) that ``spec`` carries, in file order."""
    channels = list(channels)
    spec = parse_labels(spec)
    if spec == "none":
        return []
    if spec == "all":
        return channels
    if spec == "auto":
        return [c for c in channels if auto_label(c)]
    out: list[str] = []
    for name in spec.split(","):
        got = [c for c in channels if _takes(name, c)]
        if not got:
            shown = ", ".join(channels[:24]) + (" …" if len(channels) > 24 else "")
            raise InputError(f"{where or 'frame'}: --labels {name} takes no channel; the channels besides colour, "
                             f"alpha, depth and velocity are: {shown or '(none)'}")
        out += [c for c in got if c not in out]
    return [c for c in channels if c in out]


def nearest_labels(labels: dict[str, np.ndarray], flat: np.ndarray, valid: np.ndarray) -> dict[str, np.ndarray]:
    """The numpy reference of the label path: each plane sampled at the source pixel ``flat``
    (flat index of rint(s(p)) into the source plane, per output pixel) where ``valid``, else
    :data:`LABEL_FILL`; dtype kept."""
    out = {}
    for name, plane in labels.items():
        o = np.ascontiguousarray(plane).ravel().take(np.where(valid, flat, 0).ravel()).reshape(flat.shape)
        o[~valid] = LABEL_FILL
        out[name] = o
    return out
