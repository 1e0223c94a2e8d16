"""The exposure measurements of docs/measurements.md ("Exposure defaults, the film print and grain").

Runs ``clpost`` in subprocesses, so ``PYTHONPATH`` picks the tree measured (e.g. a ``git archive``
of an older revision): a demo plate through the default camera (gain), README's physical example
(clipped pixels), an 18 % grey card through film, and a film print at equal T·t.

    PYTHONPATH=. python tools/exposure_check.py            # renders a demo plate first
    PYTHONPATH=/tmp/old python tools/exposure_check.py --plate D/render/demo.0001.exr
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def clpost(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "clpost.cli", *args], check=True, stdout=subprocess.DEVNULL)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plate", default=None, help="a pinhole render (default: clpost demo's first frame)")
    args = ap.parse_args(argv)
    from clpost import Frame, exr

    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        plate = args.plate
        if plate is None:
            clpost("demo", str(d / "demo"), "--frames", "1", "--quality", "draft")
            plate = str(d / "demo" / "render" / "demo.0001.exr")
        exr.write_frame(d / "grey.exr", Frame(np.full((64, 96, 3), 0.18, np.float32)))
        draft = ("--quality", "draft", "--quiet")
        clpost("process", plate, "-o", str(d / "default.exr"), *draft)
        clpost("process", plate, "-o", str(d / "readme.exr"), *draft, "--lens", "zeiss-planar-50-f1.4",
               "--f-number", "2", "--focus", "3", "--depth-of-field", "on", "--shutter", "1/50", "--iso", "200",
               "--luminance-scale", "1000")
        clpost("process", str(d / "grey.exr"), "-o", str(d / "grey_film.exr"), *draft, "--film", "kodak-gold-200")
        film = ("--film", "kodak-gold-200", "--luminance-scale", "1000")
        clpost("process", plate, "-o", str(d / "t09.exr"), *draft, *film, "--shutter", "1/1000", "--transmittance", "0.9")
        clpost("process", plate, "-o", str(d / "t01.exr"), *draft, *film, "--shutter", "9/1000", "--transmittance", "0.1")

        def rgb(name):
            return exr.read_frame(d / name).color[..., :3].astype(np.float64)

        src = exr.read_frame(plate).color[..., :3].astype(np.float64)
        seen = src > 1e-6
        gain = float(np.median(rgb("default.exr")[seen] / src[seen]))
        print(f"default camera on the plate: median out/in {gain:.6g} ({np.log2(gain):+.2f} EV)")
        print(f"README's physical example: {100 * np.mean((rgb('readme.exr') >= 1).any(-1)):.1f} % of pixels clipped")
        print(f"18 % grey card, --film kodak-gold-200: print {rgb('grey_film.exr').mean():.4f}")
        a, b = rgb("t09.exr"), rgb("t01.exr")
        print(f"film print at equal T·t: T 0.9 @ 1/1000 s {a.mean():.4f}, T 0.1 @ 9/1000 s {b.mean():.4f} "
              f"(max |diff| {np.abs(a - b).max():.2e})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
