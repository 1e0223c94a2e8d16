"""Any stage of an older commit against the working tree, in ONE process, interleaved per repeat
(the machines are shared: only ratios measured this way are quoted).

    PYTHONPATH=. python tools/ab_stages.py --old a46f6c0 --stages dof --scene worst \\
        --sizes 1280x720,1920x1080 --qualities draft,final [--repeats 5] [--reference DIR]
    PYTHONPATH=. python tools/ab_stages.py --old 5b84556 --stages astigmatism,coma,lateral_color \\
        --scene no_defocus --sizes 1920x1080 --qualities draft,final [--truth final]
    PYTHONPATH=. python tools/ab_stages.py --old main --stages grain --with exposure,film --scene full \
        --sizes 1280x720 --qualities draft,final
    PYTHONPATH=. python tools/ab_stages.py --save-reference DIR [--samples 128,64]

The old tree is ``git archive``-d into a temporary folder and imported as the package
``clpost_old`` (its own kernels); only the public API (``Camera``, ``Frame``, ``Pipeline``) of
both versions is used, so it keeps working across internal refactors. Scene: one of ``clpost
bench``'s (:data:`clpost.bench.SCENES`) on its synthetic frame. ms = the stage's OpenCL event
time (``Pipeline.last_timings[stage]``, uploads excluded), median of the repeats after one
warm-up; the ratio is the median of the per-repeat old/new ratios (min and max printed too).
``max|new-old|`` compares the outputs of the last repeat, relative to max|old|; ``--truth
QUALITY`` also compares both with the old stage at that quality (how far a cheaper model is from
the dense one: max, 99.9th percentile and mean of |difference|).

dof accuracy: ``--save-reference DIR`` writes the thin-lens accumulation references of the demo
scene (``clpost.dof_bench.run_dof_bench``, the data of ``clpost bench --dof``); ``--reference DIR``
then prints both versions' PSNR/FLIP against them and their dof ms on that scene.
"""
from __future__ import annotations

import argparse
import dataclasses
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def load_old(rev: str, root: Path):
    """The package of git revision ``rev``, imported as ``clpost_old``."""
    tree = root / "tree"
    tree.mkdir()
    archive = subprocess.run(["git", "archive", rev], check=True, capture_output=True).stdout
    subprocess.run(["tar", "x", "-C", str(tree)], input=archive, check=True)
    pkg = root / "pkg" / "clpost_old"
    shutil.copytree(tree / "clpost", pkg)
    shutil.copytree(tree / "kernels", pkg / "kernels")  # kernels_dir() looks beside the package
    for extra in ("lens_data",):  # package data the old tree reads beside itself
        if (tree / extra).is_dir():
            shutil.copytree(tree / extra, pkg / extra)
    sys.path.insert(0, str(root / "pkg"))
    import clpost_old

    return clpost_old


def old_camera(old, cam):
    """The working tree's camera as the old ``Camera`` (fields it does not know are dropped; a
    calibration is rebuilt from its fields, or dropped when the old model cannot take them)."""
    known = {f.name for f in dataclasses.fields(old.Camera)}
    kw = {f.name: getattr(cam, f.name) for f in dataclasses.fields(cam) if f.name in known}
    model = kw.pop("distortion", None)
    if model is not None:
        try:
            from importlib import import_module

            cls = import_module("clpost_old.calibration").OpenCVModel
            kw["distortion"] = cls(**{f.name: getattr(model, f.name) for f in dataclasses.fields(model)
                                      if f.name in {g.name for g in dataclasses.fields(cls)}})
        except Exception as e:  # noqa: BLE001 — an old model without these fields: run without it
            print(f"note: the old version runs without the calibration ({e})", file=sys.stderr)
    return old.Camera(**kw)


def old_frame(old, frame):
    return old.Frame(frame.color, depth=frame.depth, velocity=frame.velocity)


def interleaved(pipes, frames, stage: str, repeats: int):
    """Run the (old, new) pipelines alternately, which one first alternating per repeat (as
    :mod:`clpost.bench_ab`); per-version stage ms and last outputs."""
    times = [[], []]
    outs = [None, None]
    for i in range(repeats + 1):
        for j in ((0, 1) if i % 2 == 0 else (1, 0)):
            pipe, frame = pipes[j], frames[j]
            outs[j] = pipe.run(frame).color
            if i:
                t = pipe.last_timings
                times[j].append(t[stage] if stage != PLAN else
                                sum(v for k, v in t.items() if k not in ("upload", "download")))
    return times, outs


PLAN = "plan"
"""``--stages plan``: the scene's whole plan (every stage it plans, as the bench runs it), timed as
the sum of its kernels — what to compare where the two versions launch different kernels (a fused
group)."""


def timing(old, stages, scene, sizes, qualities, repeats, truth=None, lens=None, f_number=None, with_=()):
    import clpost
    from clpost.bench import SCENES, synthetic_frame

    for w, h in sizes:
        sc = SCENES[scene]
        cam, _ = sc.camera(w, h)
        if lens is not None:  # a traced lens instead of the scene's parametric coefficients
            cam = cam.with_(lens=lens, field_curvature_mm=None, astigmatism_mm=None, coma_mm=None,
                            lateral_color_mm=None, **({} if f_number is None else {"f_number": f_number}))
        frame = synthetic_frame(w, h, velocity_px=getattr(sc, "velocity_px", 0.0))
        frames = (old_frame(old, frame), frame)
        cam_old = old_camera(old, cam)
        for stage in stages:
            ref = None
            if truth is not None:
                ref = old.Pipeline(cam_old, quality=truth, stages=None if stage == PLAN else [*with_, stage]).run(
                    frames[0]).color.astype(np.float64)
            for q in qualities:
                sel = None if stage == PLAN else [*with_, stage]
                pipes = (old.Pipeline(cam_old, quality=q, stages=sel),
                         clpost.Pipeline(cam, quality=q, stages=sel))
                if stage != PLAN and stage not in pipes[1].plan(frame):
                    print(f"{w}x{h} {stage} {q}: not planned for scene {scene!r}; skipped")
                    continue
                times, (a, b) = interleaved(pipes, frames, stage, repeats)
                r = [o / n for o, n in zip(*times)]
                d = np.abs(b.astype(np.float64) - a).max() / max(float(np.abs(a).max()), 1e-30)
                print(f"{w}x{h} {stage:13s} {q:7s} old {statistics.median(times[0]):8.2f} ms  "
                      f"new {statistics.median(times[1]):8.2f} ms  old/new {statistics.median(r):5.2f} "
                      f"(min {min(r):.2f}, max {max(r):.2f})  max|new-old|/max|old| {d:.1e}", flush=True)
                if ref is not None:
                    for v, out in (("old", a), ("new", b)):
                        e = np.abs(out - ref)
                        print(f"{'':10s} {v} vs old {truth}: max {e.max():.3g}, "
                              f"99.9 % {np.percentile(e, 99.9):.3g}, mean {e.mean():.3g}")


def accuracy(old, ref_dir: Path, repeats: int):
    """PSNR/FLIP of both versions' dof against the accumulation references in ``ref_dir``, and
    their dof ms on that (demo) scene, interleaved like :func:`timing`."""
    import clpost
    from clpost.dof_bench import BENCH_CAMERA, flip_ldr, psnr_linear

    for path in sorted(ref_dir.glob("reference_*x*.npz")):
        z = np.load(path)
        ref = z["ref"].astype(np.float64)
        for q in ("draft", "preview", "final"):
            mods = (old, clpost)
            pipes = [m.Pipeline(m.Camera(**BENCH_CAMERA), quality=q, stages=["dof"]) for m in mods]
            frames = [m.Frame(z["pinhole"], depth=z["depth"]) for m in mods]
            times, outs = interleaved(pipes, frames, "dof", repeats)
            flips = [flip_ldr(ref, o) for o in outs]
            flip = "n/a" if None in flips else f"old {flips[0]:.4f}, new {flips[1]:.4f}"
            ratio = statistics.median(o / n for o, n in zip(*times))
            print(f"{path.stem[10:]} {q}: PSNR old {psnr_linear(ref, outs[0]):.2f} dB, "
                  f"new {psnr_linear(ref, outs[1]):.2f} dB; FLIP {flip}; dof ms old "
                  f"{statistics.median(times[0]):.1f}, new {statistics.median(times[1]):.1f} "
                  f"(old/new median {ratio:.2f})", flush=True)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--old", default=None, help="git revision of the old version")
    p.add_argument("--stages", default="dof", help="comma-separated stage names (default dof); plan: the "
                   "scene's whole plan, timed as the sum of its kernels")
    p.add_argument("--scene", default="worst", help="a clpost bench scene (default worst)")
    p.add_argument("--with", dest="with_", default="",
                   help="stages planned before each timed one, not timed (grain: exposure,film)")
    p.add_argument("--sizes", default="1280x720,1920x1080")
    p.add_argument("--qualities", default="draft,final")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--lens", default=None, help="a traced lens instead of the scene's coefficients")
    p.add_argument("--f-number", type=float, default=None)
    p.add_argument("--truth", default=None, help="compare both outputs with the old stage at this quality")
    p.add_argument("--reference", default=None, help="a --save-reference folder: dof PSNR/FLIP of both")
    p.add_argument("--save-reference", default=None, help="write the dof accumulation references here")
    p.add_argument("--samples", default="128,64", help="reference aperture samples per size (--save-reference)")
    a = p.parse_args(argv)
    if a.save_reference:
        from clpost.dof_bench import format_dof_table, run_dof_bench
        from clpost.runtime import get_runtime

        Path(a.save_reference).mkdir(parents=True, exist_ok=True)
        rows, conv = run_dof_bench(samples=tuple(int(s) for s in a.samples.split(",")), repeats=a.repeats,
                                   save_dir=a.save_reference)
        print(format_dof_table(rows, conv, get_runtime().name))
    if a.old is None:
        if not a.save_reference:
            p.error("--old is required (or --save-reference alone)")
        return 0
    sizes = [tuple(int(v) for v in s.split("x")) for s in a.sizes.split(",")]
    with tempfile.TemporaryDirectory(prefix="clpost_ab_") as tmp:
        old = load_old(a.old, Path(tmp))
        timing(old, a.stages.split(","), a.scene, sizes, a.qualities.split(","), a.repeats,
               truth=a.truth, lens=a.lens, f_number=a.f_number, with_=[v for v in a.with_.split(",") if v])
        if a.reference:
            accuracy(old, Path(a.reference), a.repeats)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
