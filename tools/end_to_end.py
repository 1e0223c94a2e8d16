"""End-to-end frame time of ``Plan.run`` (upload, kernels, download, host work: wall clock) for
the bench scenes, with the frame's arrays and the output in ordinary (pageable) NumPy memory
and in page-locked memory (``Runtime.pinned_empty``, ``Plan.run(out=...)``), and of
``Plan.submit`` with pinned frames: ``--frames`` frames submitted back to back, each result taken
once ``--in-flight`` later frames are submitted (a streaming consumer; a column per value), wall /
frames — uploads
and downloads overlapping other frames' kernels (``clpost.stream``). On a CPU device the three
are the same (submit runs each frame at once; ``--force-pipelined`` runs the GPU path there, to
check it); on a discrete GPU the pinned form copies at the bus's rate. Median of ``--repeats``
after warm-up. ``--focus-pull``: each submitted frame has its own focus distance (a pull over
``FOCUS_PULL_M``), so the stages' per-frame tables change every frame. The "host ms" columns are
the submitting thread's CPU time per ``submit`` (``Plan.last_host_ms``, median): per-frame host
work, which should not grow with the frame's pixels (compare two ``--size``s). ``--timeline``: after
each row, where a pipelined frame's time goes (busy time of the upload queue, the compute queue and
the downloads, and what the compute queue waited for), from the commands' OpenCL profiling times;
stderr lists every command of three middle frames. ``--aux-out``: the pipelined frames also hand
the plan page-locked arrays for distortion's depth and velocity (``Plan.submit(out={...})``).

    python tools/end_to_end.py --force-pipelined --focus-pull --size 480x270 --scenes worst,full \
        --qualities draft --in-flight 2

    python tools/end_to_end.py --device nvidia --scenes worst,no_defocus,full --qualities draft,final
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np

from clpost.bench import SCENES, synthetic_frame
from clpost.pipeline import Pipeline


def _pinned_frame(rt, frame):
    arrays = {}
    for name in ("color", "depth", "velocity"):
        a = getattr(frame, name)
        if a is not None:
            p = rt.pinned_empty(a.shape, a.dtype)
            p[...] = a
            arrays[name] = p
    pinned = frame.replace(copy=False, **arrays)  # a Frame copies its arrays (pageable) unless told
    assert all(getattr(pinned, k) is v for k, v in arrays.items())
    return pinned


def _wall(plan, frame, cam, repeats: int, out=None) -> float:
    times = []
    for i in range(repeats + 2):
        t0 = time.perf_counter()
        plan.run(frame, cam, out=out)
        if i >= 2:
            times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


FOCUS_PULL_M = (0.5, 0.7, 1.0, 1.5, 2.5, 4.0)
"""``--focus-pull``'s focus distances, frame k taking ``FOCUS_PULL_M[k % 6]``."""


def _stream(plan, inputs: list, cams: list, frames: int, outs: list, host: list | None = None) -> list:
    """``frames`` frames through ``Plan.submit``, in order: frame k is ``inputs[k % len(inputs)]``
    with ``cams[k % len(cams)]`` into ``outs[k % len(outs)]``, its result taken when ``len(outs) -
    1`` later frames are in flight (then its ``out`` is used again); the submitted frames, every
    result taken. ``host``: a list each submit's ``Plan.last_host_ms`` is appended to."""
    from collections import deque

    depth, done, pending = len(outs) - 1, [], deque()
    for k in range(frames):
        if len(pending) >= depth:
            done.append(pending.popleft())
            done[-1].result()
        pending.append(plan.submit(inputs[k % len(inputs)], cams[k % len(cams)], out=outs[k % len(outs)]))
        if host is not None:
            host.append(plan.last_host_ms)
    while pending:
        done.append(pending.popleft())
        done[-1].result()
    return done


def _pipelined(plan, inputs: list, cams: list, repeats: int, frames: int, outs: list) -> tuple[float, float]:
    """(wall ms per frame, median host ms per submit) of :func:`_stream` (median of ``repeats``
    runs after one warm-up)."""
    _stream(plan, inputs, cams, frames, outs)
    times, host = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        _stream(plan, inputs, cams, frames, outs, host)
        times.append((time.perf_counter() - t0) * 1e3 / frames)
    return statistics.median(times), statistics.median(host)


def _outs(rt, size: tuple[int, int], n: int, aux: list) -> list:
    """``n`` page-locked output images (NaN, so an image no frame wrote shows), each in a dict with
    page-locked arrays for ``aux``'s (name, trailing shape) where given (``--aux-out``)."""
    ow, oh = size
    outs = [rt.pinned_empty((oh, ow, 3)) for _ in range(n)]
    for o in outs:
        o.fill(np.nan)
    return [dict(color=o, **{k: rt.pinned_empty((oh, ow) + s) for k, s in aux}) for o in outs] if aux else outs


def _timeline(plan, inputs: list, cams: list, frames: int, outs: list, dump=None) -> dict[str, float]:
    """Where a pipelined frame's time goes, from its commands' OpenCL profiling times (every queue
    of the context counts on the device's clock; ``queued`` is when the host enqueued the
    command): per frame, medians over the frames after the first two, in ms —
    ``cadence``: between consecutive frames' first uploads being enqueued (the host's submit
    rate); ``upload``/``compute``/``download``: busy time of the upload queue, the compute queue
    (kernels and the slot's device-to-device copies) and the downloads; ``compute idle``: the
    compute queue's gap before the frame's first command; of it ``waiting for host``: that
    command's start minus the later of its enqueue and the previous frame's last compute command
    (the device had nothing to do), and ``waiting for upload``: the frame's last upload's end
    minus the previous frame's last compute end (the bus was late). ``dump``: a file to list every
    command of three middle frames in (label, queued, start, end)."""
    done = _stream(plan, inputs, cams, frames, outs)
    if dump:  # every command of three middle frames, ms from the first one's first enqueue
        mid = done[len(done) // 2 - 1:len(done) // 2 + 2]
        t0 = min(e.profile.queued for p in mid for _, e in p._events) * 1e-6
        for i, p in enumerate(mid):
            for label, e in sorted(p._events, key=lambda le: le[1].profile.start):
                print(f"    frame +{i} {label:<28} queued {e.profile.queued * 1e-6 - t0:8.3f} "
                      f"start {e.profile.start * 1e-6 - t0:8.3f} end {e.profile.end * 1e-6 - t0:8.3f}", file=dump)
    rows = []
    for p in done:
        ev = [(label, e.profile.queued * 1e-6, e.profile.start * 1e-6, e.profile.end * 1e-6)
              for label, e in p._events]
        up = [e for e in ev if e[0] == "upload"]
        down = [e for e in ev if e[0] == "download"]
        comp = sorted((e for e in ev if e[0] not in ("upload", "download")), key=lambda e: e[2])
        rows.append(dict(first_q=min(e[1] for e in up), up=sum(e[3] - e[2] for e in up),
                         up_end=max(e[3] for e in up), down=sum(e[3] - e[2] for e in down),
                         comp=sum(e[3] - e[2] for e in comp), c_first=comp[0], c_end=max(e[3] for e in comp)))
    stats: dict[str, list] = {k: [] for k in ("cadence", "upload", "compute", "download", "compute idle",
                                              "waiting for host", "waiting for upload")}
    for a, b in zip(rows[1:-1], rows[2:]):
        stats["cadence"].append(b["first_q"] - a["first_q"])
        stats["upload"].append(b["up"])
        stats["compute"].append(b["comp"])
        stats["download"].append(b["down"])
        _, queued, start, _ = b["c_first"]
        stats["compute idle"].append(start - a["c_end"])
        stats["waiting for host"].append(max(0.0, start - max(queued, a["c_end"])) if queued > a["c_end"] else 0.0)
        stats["waiting for upload"].append(max(0.0, b["up_end"] - a["c_end"]))
    return {k: statistics.median(v) for k, v in stats.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device")
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--scenes", default="worst,no_defocus,full")
    ap.add_argument("--qualities", default="draft,final")
    ap.add_argument("--repeats", type=int, default=5,
                    help="timed runs per column (the first plan builds compile: keep the tool short)")
    ap.add_argument("--frames", type=int, default=12, help="frames per pipelined run")
    ap.add_argument("--in-flight", default="2,3",
                    help="Plan.in_flight of the pipelined runs, comma-separated: a column each")
    ap.add_argument("--force-pipelined", action="store_true",
                    help="pipeline on a CPU device too (a check of the GPU path, not a speed-up)")
    ap.add_argument("--focus-pull", action="store_true",
                    help="each frame its own focus distance (FOCUS_PULL_M): per-frame tables change")
    ap.add_argument("--aux-out", action="store_true",
                    help="pipelined frames also download distortion's depth and velocity into page-locked "
                         "arrays of the caller's (Plan.submit(out={...})) instead of new ones")
    ap.add_argument("--timeline", action="store_true",
                    help="after each row, where a pipelined frame's time goes (first --in-flight value; "
                         "OpenCL profiling times of its uploads, compute-queue commands and downloads)")
    a = ap.parse_args(argv)
    w, h = (int(v) for v in a.size.split("x"))
    depths = [int(v) for v in a.in_flight.split(",")]
    print("| scene | quality | pageable ms | fps | pinned ms | fps |"
          + "".join(f" pipelined, {d} in flight, ms | fps | host ms |" for d in depths)
          + "\n|---|---|---:|---:|---:|---:|" + "---:|---:|---:|" * len(depths))
    bad = []
    for name in a.scenes.split(","):
        scene = SCENES[name]
        for q in a.qualities.split(","):
            cam, _ = scene.camera(w, h)
            frame = synthetic_frame(w, h, velocity_px=scene.velocity_px)
            pipe = Pipeline(cam, quality=q, stages=list(scene.wants), device=a.device)
            rcam = pipe.camera_for(frame, cam)
            plan = pipe.plan_for(frame, rcam)
            plain = _wall(plan, frame, rcam, a.repeats)
            pf = _pinned_frame(pipe.runtime, frame)
            ow, oh = plan.launches[-1].out_size if plan.launches else (w, h)
            out = pipe.runtime.pinned_empty((oh, ow, 3))
            pinned = _wall(plan, pf, rcam, a.repeats, out=out)
            # two different frames alternate in the pipelined runs, so a mix-up between frames shows
            inputs = [pf, _pinned_frame(pipe.runtime, frame.replace(color=frame.color[::-1].copy()))]
            cams = [rcam.with_(focus_distance_m=f) for f in FOCUS_PULL_M] if a.focus_pull else [rcam]
            plan.pipelined = plan.pipelined or a.force_pipelined
            aux = [(n, s) for n, s in (("depth", ()), ("velocity", (2,)))
                   if a.aux_out and "distortion" in plan.stage_names and getattr(frame, n) is not None]
            row = f"| {name} | {q} | {plain:.2f} | {1e3 / plain:.0f} | {pinned:.2f} | {1e3 / pinned:.0f} |"
            for d in depths:
                plan.in_flight = d
                outs = _outs(pipe.runtime, (ow, oh), d + 1, aux)
                piped, host = _pipelined(plan, inputs, cams, a.repeats, a.frames, outs)
                # each out holds the last frame that used it: a frame given another's image fails
                last = {k % len(outs): k for k in range(a.frames)}
                got = [outs[j] if aux else dict(color=outs[j]) for j in last]
                want = [plan.run(inputs[k % len(inputs)], cams[k % len(cams)]) for k in last.values()]
                if not all(np.array_equal(g[n], getattr(w_, n)) for g, w_ in zip(got, want) for n in g):
                    bad.append(f"{name} {q} ({d} in flight)")
                row += f" {piped:.2f} | {1e3 / piped:.0f} | {host:.2f} |"
            print(row, flush=True)
            if a.timeline:
                plan.in_flight = depths[0]
                outs = _outs(pipe.runtime, (ow, oh), depths[0] + 1, aux)
                t = _timeline(plan, inputs, cams, a.frames, outs, sys.stderr)
                print(f"|   timeline, {depths[0]} in flight, ms per frame: "
                      + ", ".join(f"{k} {v:.2f}" for k, v in t.items()) + " |", flush=True)
            pipe.close()  # the frames in flight and the download thread end with the row
    if bad:
        print(f"pipelined frames differ from Plan.run's: {', '.join(bad)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
