r"""DoF old vs new on the Cycles suite's scenes upscaled 3× (1440×810): the dof stage's event ms
of an old revision and of this tree in one process, which runs first alternating per repeat, and
each kernel's median ms (per frame) of both.

Usage::

    PYTHONPATH=. python tools/ab_cycles_dof.py --old 66f327a --scenes thin,transparent,highlights \
        --qualities draft,preview,final --repeats 100

Prints per scene × quality the median ms of each, the median of per-repeat old/new ratios (> 1:
new is faster), the ratio of the fastest runs and the max abs difference of the two outputs (0: a
speed change that keeps the bits). The old revision is exported with
``tools/ab_stages.py``'s loader; scenes come from ``tests/data/cycles`` (``--data`` for another)."""
from __future__ import annotations

import argparse
import importlib
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import ab_stages as ab  # noqa: E402
import cycles_compare as cc  # noqa: E402

import clpost  # noqa: E402
from clpost import fidelity as fd  # noqa: E402
from clpost.runtime import event_ms  # noqa: E402


def _record_kernels(module, tag: str, into: dict) -> None:
    """Wrap ``module.Recording.replay`` so each replayed kernel's event lands in ``into``."""
    rec_cls = module.Recording
    replay = rec_cls.replay

    def wrapped(self, queue, frame, *rest, _replay=replay):  # rest: a newer replay's download hook
        events, host = _replay(self, queue, frame, *rest)
        for (_, ev), cmd in zip(events, self.commands):
            if getattr(cmd, "kernel", None) is not None:
                into.setdefault(tag + cmd.kernel.function_name, []).append(ev)
        return events, host

    rec_cls.replay = wrapped


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", default="main", help="the revision to compare with (default main)")
    ap.add_argument("--scenes", default="thin,transparent,highlights")
    ap.add_argument("--qualities", default="draft,preview,final")
    ap.add_argument("--repeats", type=int, default=30)
    ap.add_argument("--data", default=None, help="another Cycles data folder (tests/data/cycles_heldout)")
    args = ap.parse_args(argv)
    old = ab.load_old(args.old, Path(tempfile.mkdtemp()))
    kernels: dict[str, list] = {}
    _record_kernels(importlib.import_module("clpost_old.runtime_record"), "old ", kernels)
    _record_kernels(importlib.import_module("clpost.runtime_record"), "new ", kernels)
    for name in args.scenes.split(","):
        entry, frame, _, _ = cc.load_scene(name, **({} if args.data is None else {"data": Path(args.data)}))
        up = lambda a: np.repeat(np.repeat(a, 3, 0), 3, 1)  # noqa: E731
        f = clpost.Frame(up(frame.color[..., :3]).copy(), depth=up(frame.depth).copy())
        w, h = entry["size"]
        cam = fd.cycles_camera(entry["shot"], 3 * w, 3 * h, dof=True, motion=False)
        for q in args.qualities.split(","):
            pipes = (old.Pipeline(ab.old_camera(old, cam), quality=q, stages=["dof"]),
                     clpost.Pipeline(cam, quality=q, stages=["dof"]))
            frames = (ab.old_frame(old, f), f)
            for p, fr in zip(pipes, frames):  # build and warm
                p.run(fr)
            kernels.clear()
            times, outs = ab.interleaved(pipes, frames, "dof", args.repeats)
            diff = float(np.max(np.abs(np.asarray(outs[0], np.float64) - np.asarray(outs[1], np.float64))))
            per = {k: round(statistics.median(event_ms(e) for e in v) * len(v) / (args.repeats + 1), 2)
                   for k, v in sorted(kernels.items())}
            r = [o / n for o, n in zip(*times)]
            print(f"{name:12s} {q:7s} old {statistics.median(times[0]):7.2f} new {statistics.median(times[1]):7.2f} ms"
                  f"  old/new median {statistics.median(r):.3f}  fastest runs {min(times[0]) / min(times[1]):.3f}"
                  f"  max abs diff {diff:.3g}",
                  flush=True)
            print("    per kernel, ms/frame:", per, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
