"""motion_blur on a renderer's export: the Cycles motion scene (tests/data/cycles/motion), scored
inside the box around moving pixels against Cycles' own 180° motion blur (docs/motion_blur.md,
"Renderer input"). Floors are the measured levels minus a margin; Blender 5.0's Vector Blur on
the same export measured 32.91 dB / FLIP 0.0248 there (tools/cycles_compare.py --blender ...)."""
import json
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from clpost import fidelity as fd
from clpost.exr import read_frame

DATA = Path(__file__).parent / "data" / "cycles"
MANIFEST = json.loads((DATA / "manifest.json").read_text())
VECTOR_BLUR = (32.91, 0.0248)
# quality -> (PSNR dB, FLIP) in the motion box, measured with the front layer's motion-line test, the
# R2-lattice jitter and the frame's tap cap (docs/motion_blur.md); before them 32.68 / 34.01 / 34.23 dB
# and FLIP 0.0273 / 0.0224 / 0.0202; before the swept-pixel footprint and the nearest-weighted
# background 32.39 / 33.53 / 33.79 dB and FLIP 0.0290 / 0.0242 / 0.0220; main before issue 16 item 3:
# 30.40 / 30.57 / 30.82 dB, 0.0384 / 0.0388 / 0.0389; draft's frame cap up to 19 taps (issue 16,
# fourth round): draft 33.97 dB / 0.0219 -> 34.19 / 0.0202
MEASURED = {"draft": (34.19, 0.0202), "preview": (34.24, 0.0197), "final": (34.24, 0.0197)}
pytestmark = pytest.mark.skipif("motion" not in MANIFEST["scenes"], reason="no motion scene stored")


def _truth(path: Path) -> np.ndarray:
    for part in OpenEXR.File(str(path), separate_channels=True).parts:
        ch = part.channels
        for pre in [""] + [n[:-1] for n in ch if n.endswith(".R")]:
            if all(pre + c in ch for c in "RGB"):
                return np.stack([ch[pre + c].pixels for c in "RGB"], -1).astype(np.float32)
    raise AssertionError(f"{path}: no R/G/B")


@pytest.mark.parametrize("quality", list(MEASURED))
def test_motion_box_floor_vs_cycles(quality):
    entry = MANIFEST["scenes"]["motion"]
    frame = read_frame(DATA / entry["pinhole"]["file"])
    truth = _truth(DATA / entry["truths"]["motion"]["file"])
    out = fd.cycles_pipeline(entry, "motion", quality).run(frame).color[..., :3]
    y0, y1, x0, x1 = fd.motion_box(frame.velocity, entry["shot"]["shutter_frames"])
    psnr = fd.psnr_srgb(truth[y0:y1, x0:x1], out[y0:y1, x0:x1])
    assert psnr >= MEASURED[quality][0] - 0.3, f"{quality}: {psnr:.2f} dB"
    assert psnr > VECTOR_BLUR[0] + 1.0, psnr            # issue 16: >= 1 dB above (draft too since its 19-tap cap)
    flip = fd.flip_ldr(truth[y0:y1, x0:x1], out[y0:y1, x0:x1])
    if flip is not None:                             # flip-evaluator installed ('.[bench]')
        assert flip <= MEASURED[quality][1] + 0.002, f"{quality}: FLIP {flip:.4f}"
        # issue 16's target, 20 % lower than Vector Blur: met at preview and final (0.0197 <= 0.0198);
        # draft 18.7 % lower (0.0202), pinned at 15 %
        assert flip <= (0.85 if quality == "draft" else 0.8) * VECTOR_BLUR[1], flip
