"""dof speed (and output) of an older commit against the working tree, in ONE process,
interleaved per repeat (the machines are shared: only ratios measured this way are quoted).

    PYTHONPATH=. python tools/dof_old_vs_new.py --old a46f6c0 [--sizes 1280x720,1920x1080]
        [--qualities draft,final] [--repeats 5] [--reference DIR]

The old tree is ``git archive``-d into a temporary folder and imported as the package
``clpost_old`` (its own OpenCL context and kernels). Scene: ``clpost bench``'s "worst"
(:data:`clpost.bench.SCENES`), dof only; ms = the sum of the stage's OpenCL event times
(``Pipeline.last_timings["dof"]``), median of the repeats after one warm-up. With
``--reference DIR`` (the ``--save`` folder of tools/dof_bench.py) it also prints both versions'
PSNR/FLIP against the accumulation reference on the same pinhole inputs, and both versions' dof
ms on that (demo) scene.
"""
import argparse
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def load_old(ref: str, root: Path):
    tree = root / "tree"
    tree.mkdir()
    archive = subprocess.run(["git", "archive", ref], check=True, capture_output=True).stdout
    subprocess.run(["tar", "x", "-C", str(tree)], input=archive, check=True)
    pkg = root / "pkg" / "clpost_old"
    shutil.copytree(tree / "clpost", pkg)
    shutil.copytree(tree / "kernels", pkg / "kernels")  # kernels_dir() looks beside the package
    sys.path.insert(0, str(root / "pkg"))
    import clpost_old

    return clpost_old


def timing(old, sizes, qualities, repeats):
    import clpost
    from clpost.bench import SCENES, synthetic_frame

    for w, h in sizes:
        cam, _ = SCENES["worst"].camera(w, h)
        frame = synthetic_frame(w, h)
        # the old Camera rejects the new tree's distortion model class; dof does not read it
        cam_old = old.Camera(**{f: getattr(cam, f) for f in cam.__dataclass_fields__
                                if f != "distortion" and f in old.Camera.__dataclass_fields__})
        frame_old = old.Frame(frame.color, depth=frame.depth)
        for q in qualities:
            p_new = clpost.Pipeline(cam, quality=q, stages=["dof"])
            p_old = old.Pipeline(cam_old, quality=q, stages=["dof"])
            t_old, t_new = [], []
            for i in range(repeats + 1):
                a = p_old.run(frame_old).color
                b = p_new.run(frame).color
                if i:
                    t_old.append(p_old.last_timings["dof"])
                    t_new.append(p_new.last_timings["dof"])
            r = [o / n for o, n in zip(t_old, t_new)]
            d = np.abs(b.astype(np.float64) - a).max() / np.abs(a).max()
            print(f"{w}x{h} {q}: old {statistics.median(t_old):.1f} ms, new {statistics.median(t_new):.1f} ms, "
                  f"old/new median {statistics.median(r):.2f} [min {min(r):.2f}, max {max(r):.2f}]; "
                  f"max |new - old| / max(old) {d:.1e}", flush=True)


def accuracy(old, ref_dir: Path, repeats: int):
    """PSNR/FLIP of both versions against the reference, and their dof ms on this (demo) scene,
    interleaved like :func:`timing`."""
    import clpost
    from clpost.dof_bench import BENCH_CAMERA, flip_ldr, psnr_linear

    for path in sorted(ref_dir.glob("reference_*x*.npz")):
        z = np.load(path)
        ref = z["ref"].astype(np.float64)
        for q in ("draft", "preview", "final"):
            pipes = [(mod.Pipeline(mod.Camera(**BENCH_CAMERA), quality=q, stages=["dof"]),
                      mod.Frame(z["pinhole"], depth=z["depth"])) for mod in (old, clpost)]
            times = [[], []]
            for i in range(repeats + 1):
                outs = []
                for j, (pipe, frame) in enumerate(pipes):
                    outs.append(pipe.run(frame).color)
                    if i:
                        times[j].append(pipe.last_timings["dof"])
            flips = [flip_ldr(ref, o) for o in outs]
            flip = "n/a" if None in flips else f"old {flips[0]:.4f}, new {flips[1]:.4f}"
            ratio = statistics.median(o / n for o, n in zip(*times))
            print(f"{path.stem[10:]} {q}: PSNR old {psnr_linear(ref, outs[0]):.2f} dB, "
                  f"new {psnr_linear(ref, outs[1]):.2f} dB; FLIP {flip}; dof ms old "
                  f"{statistics.median(times[0]):.1f}, new {statistics.median(times[1]):.1f} "
                  f"(old/new median {ratio:.2f})", flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--old", required=True, help="git commit of the old version")
    p.add_argument("--sizes", default="1280x720,1920x1080")
    p.add_argument("--qualities", default="draft,final")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--reference", default=None, help="tools/dof_bench.py --save folder (accuracy)")
    a = p.parse_args(argv)
    sizes = [tuple(int(v) for v in s.split("x")) for s in a.sizes.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        old = load_old(a.old, Path(tmp))
        timing(old, sizes, a.qualities.split(","), a.repeats)
        if a.reference:
            accuracy(old, Path(a.reference), a.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
