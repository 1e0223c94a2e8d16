"""The ghost stage's cost and error per GHOST_FLOOR (docs/flare.md "Cost").

    python tools/ghost_floor.py RENDER_EXR [f-number] [floor ...]

RENDER_EXR: a demo render (`clpost demo OUT --frames 1`), its lamps ×100 as in tools/flare_figures.py.
Per floor: wall and kernel time of a final-quality frame after the first, the (source, ghost) pairs
drawn, and, against floor 0, the error on the pixels below saturation (× saturation) and the share
of the ghost light there that is left out.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import time

import clpost.stages.ghosts as G
from clpost import Frame, Pipeline
from clpost.exr import read_frame
from clpost.photometry import exposure_gain
from flare_figures import camera


def main():
    fr = read_frame(Path(sys.argv[1]))
    c = fr.color.astype(np.float32).copy()
    c[c.max(axis=2) > 100] *= 100
    frame = Frame(c)
    n = float(sys.argv[2]) if len(sys.argv) > 2 else 8.0
    floors = [float(v) for v in sys.argv[3:]] or [0.0, 1e-4, 1e-3]
    cam = camera(n, ghosts=True)
    base = None
    for floor in floors:
        G.GHOST_FLOOR = floor
        pipe = Pipeline(cam, stages=["ghosts"], quality="final")
        pipe.run(frame)
        t0 = time.perf_counter()
        res = pipe.run(frame).color.astype(np.float64)
        dt = time.perf_counter() - t0
        pc = pipe.camera_for(frame)
        g = exposure_gain(pc)
        st = G.Ghosts("final")
        tab = st.table(pc, frame, st.sources(pc, frame))
        line = (f"f/{n:g} floor {floor:g}: {dt * 1000:.0f} ms wall, ghosts kernel "
                f"{pipe.last_timings.get('ghosts', 0):.0f} ms, {int(tab[:, 0, 11].sum())} of "
                f"{tab.shape[0] * tab.shape[1]} (source, ghost) pairs drawn")
        if floor == 0.0:
            base = res
        elif base is not None:
            off = frame.color.max(axis=2) * g < 1.0
            d = np.abs(res - base) * g
            ghost = np.abs(base - frame.color) * g
            line += (f"; error off the sources: largest {d[off].max():.2e}, mean {d[off].mean():.1e} × saturation, "
                     f"ghost light left out {d[off].sum() / ghost[off].sum():.3f}")
        print(line, flush=True)


if __name__ == "__main__":
    main()
