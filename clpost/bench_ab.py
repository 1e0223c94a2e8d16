"""``clpost bench --against REV``: this tree and a git revision of clpost in ONE process.

Timings on a shared machine drift by ×2 between runs, so "no stage got slower" is only a claim
when old and new run side by side. The revision's ``clpost/``, ``kernels/`` and ``lens_data/`` are
exported with ``git archive`` into a temporary folder and imported as a second package
(``clpost_<rev>``; clpost's own imports are relative, so it runs unchanged). Each (scene, size,
quality) runs both pipelines on the same frame, interleaved (old, new, old, new, …) after warm-up,
so load hits both alike; per kernel the median device ms of each and the median of the per-repeat
ratios new/old are reported, with max|old − new| of the outputs.
"""
from __future__ import annotations

import importlib
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from .errors import InputError


def load_revision(rev: str, repo: str | Path = ".") -> object:
    """The ``clpost`` package of git revision ``rev`` of the checkout at ``repo``, imported under
    another name."""
    name = "clpost_" + re.sub(r"\W", "_", rev)
    if name in sys.modules:
        return sys.modules[name]
    root = Path(tempfile.mkdtemp(prefix=f"{name}-"))
    try:
        archive = subprocess.run(["git", "-C", str(repo), "archive", rev, "clpost", "kernels", "lens_data"],
                                 check=True, capture_output=True).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        err = getattr(exc, "stderr", b"") or b""
        raise InputError(f"--against {rev}: git archive failed ({err.decode(errors='replace').strip() or exc}); "
                         "run from a clpost git checkout and name a commit, branch or tag") from None
    subprocess.run(["tar", "-x", "-C", str(root)], input=archive, check=True)
    (root / "clpost").rename(root / name)
    sys.path.insert(0, str(root))
    try:
        return importlib.import_module(name)
    finally:
        sys.path.remove(str(root))


def compare(rev: str, scenes: list[str], sizes, qualities, *, device=None, repeats: int = 7,
            warmup: int = 2, log=None) -> list[dict]:
    """Rows (scene, size, quality, kernel, old ms, new ms, ratio) of this tree vs ``rev``."""
    from . import bench as new_bench

    old = load_revision(rev)
    old_bench = importlib.import_module(f"{old.__name__}.bench")
    rows = []
    for sc in scenes:
        for w, h in sizes:
            for q in qualities:
                if log:
                    log(f"bench --against {rev}: {sc} {w}x{h} {q} …")
                rows += _compare_case(old, old_bench, new_bench, sc, w, h, q, device, repeats, warmup)
    return rows


def _pipeline(pkg, bench_mod, scene: str, w: int, h: int, quality: str, device, frame):
    """``pkg``'s pipeline for the scene, and the frame as ``pkg``'s Frame."""
    sc = bench_mod.SCENES[scene]
    cam, _ = sc.camera(w, h)
    known = importlib.import_module(f"{pkg.__name__}.stages").registry()
    pipe = importlib.import_module(f"{pkg.__name__}.pipeline").Pipeline(
        cam, quality=quality, stages=[s for s in sc.wants if s in known] or None, device=device)
    frame_cls = importlib.import_module(f"{pkg.__name__}.frame").Frame
    f = frame_cls(frame.color, depth=frame.depth, velocity=frame.velocity, alpha=frame.alpha,
                  metadata=dict(frame.metadata))
    return pipe, f


def _compare_case(*args):
    import warnings

    # timed, not looked at; and a warning class of the old revision's package cannot cross
    # processes (pytest-xdist) — so no warnings from either run here
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _compare_runs(*args)


def _compare_runs(old, old_bench, new_bench, scene, w, h, quality, device, repeats, warmup):
    sc = new_bench.SCENES[scene]
    frame = (new_bench.demo_frame(w, h) if sc.frame == "demo"
             else new_bench.synthetic_frame(w, h, velocity_px=sc.velocity_px, front=getattr(sc, "front", False)))
    p_old, f_old = _pipeline(old, old_bench, scene, w, h, quality, device, frame)
    p_new, f_new = _pipeline(sys.modules[__package__], new_bench, scene, w, h, quality, device, frame)
    times: dict[str, tuple[list, list]] = {}
    outs = []
    for i in range(warmup + repeats):
        pair = [None, None]
        # which revision runs first alternates per repeat: on a loaded box the second of two
        # back-to-back runs is systematically faster or slower (caches, frequency, the scheduler),
        # which biased identical kernels to new/old 0.67–1.17 when old always ran first
        order = (0, 1) if i % 2 == 0 else (1, 0)
        for k in order:
            pipe, f = ((p_old, f_old), (p_new, f_new))[k]
            out = pipe.run(f)
            if i == 0:
                outs.append((k, out.color))
            pair[k] = dict(pipe.last_timings)
        if i < warmup:
            continue
        for k, t in enumerate(pair):
            for name, ms in t.items():
                times.setdefault(name, ([], []))[k].append(ms)
    a_out, b_out = (c for _, c in sorted(outs, key=lambda kc: kc[0]))
    diff = float(np.max(np.abs(a_out.astype(np.float64) - b_out))) if a_out.shape == b_out.shape else None
    rows = []
    for name, (a, b) in times.items():
        if name in ("upload", "download"):
            continue
        if len(a) == len(b) and a:
            ratio = statistics.median(nb / na for na, nb in zip(a, b) if na > 0) if any(a) else None
        else:
            ratio = None
        rows.append(dict(scene=scene, size=f"{w}x{h}", quality=quality, kernel=name,
                         old_ms=statistics.median(a) if a else None,
                         new_ms=statistics.median(b) if b else None, ratio=ratio, max_abs_diff=diff))
    rows.append(dict(scene=scene, size=f"{w}x{h}", quality=quality, kernel="(all kernels)",
                     old_ms=sum(r["old_ms"] or 0 for r in rows), new_ms=sum(r["new_ms"] or 0 for r in rows),
                     ratio=None, max_abs_diff=diff))
    tot = rows[-1]
    tot["ratio"] = tot["new_ms"] / tot["old_ms"] if tot["old_ms"] else None
    return rows


def format_rows(rows: list[dict], rev: str) -> str:
    """Markdown table of :func:`compare`'s rows."""
    def f(v, fmt):
        return "–" if v is None else format(v, fmt)

    out = [f"| scene | size | quality | kernel | {rev} ms | this tree ms | new/old | max abs diff |",
           "|---|---|---|---|---:|---:|---:|---:|"]
    for r in rows:
        out.append(f"| {r['scene']} | {r['size']} | {r['quality']} | {r['kernel']} | {f(r['old_ms'], '.2f')} "
                   f"| {f(r['new_ms'], '.2f')} | {f(r['ratio'], '.2f')} | {f(r['max_abs_diff'], '.2g')} |")
    return "\n".join(out)
