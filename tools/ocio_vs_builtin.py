"""How far clpost's own display encodings (clpost.colorspace.DISPLAYS) are from the matching
OpenColorIO built-in display/view ("Un-tone-mapped": colorimetric, no tone scale), on linear
values in [0, 1] (clpost clips to that range; OCIO does not). Prints the largest difference in
code values (float, 1.0 = full scale) per (working space, display). docs/measurements.md#ocio-builtins.

    .venv/bin/python tools/ocio_vs_builtin.py [--config ocio://studio-config-latest]
"""
from __future__ import annotations

import argparse

import numpy as np

from clpost.colorspace import cctf_encode, working_to_display_linear
from clpost.ocio import OcioView, working_space_chromaticities

PAIRS = {"srgb": "sRGB - Display", "display-p3": "Display P3 - Display", "rec709": "Rec.1886 Rec.709 - Display"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="ocio://studio-config-latest")
    args = ap.parse_args(argv)
    from clpost.colorspace import DISPLAYS

    rng = np.random.default_rng(7)
    x = np.concatenate([rng.random((20000, 3)), np.linspace(0, 1, 1001)[:, None].repeat(3, 1)])
    for ws in ("rec709", "acescg"):
        for disp, ocio_disp in PAIRS.items():
            lin = working_to_display_linear(x, ws, disp)
            inside = np.all((lin >= 0) & (lin <= 1), axis=1)  # where clpost does not clip
            ours = cctf_encode(lin, DISPLAYS[disp][1])
            view = OcioView.resolve(args.config, ocio_disp, "Un-tone-mapped")
            theirs = view.encode(x.astype(np.float32), ws, working_space_chromaticities(ws)).astype(np.float64)
            d = np.abs(ours - theirs)[inside]
            print(f"{ws:7s} {disp:11s} vs {ocio_disp!r:32s}: max |Δ| {d.max():.3g} "
                  f"({d.max() * 255:.3g} of an 8-bit code), mean {d.mean():.2g}, n = {inside.sum()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
