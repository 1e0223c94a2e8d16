"""Run a frame sequence on a Dask cluster: the same per-frame code as the serial loop, placed
on workers.

- ``clpost process ... --workers N`` starts a :class:`distributed.LocalCluster` of N worker
  processes (one thread each: a worker's OpenCL device already uses all its cores);
  ``--scheduler tcp://HOST:8786`` joins an existing cluster. The serial path stays the default;
  both call :func:`clpost.batch.process_one`, so only *where* a frame runs differs.
- Each worker process builds its OpenCL pipeline once (device chosen per worker, programs
  cached) and reuses it for every frame it gets: :func:`worker_pipeline` is memoised per process
  on the hashable :class:`PipelineSpec`.
- Frames are independent tasks reading and writing paths on a shared filesystem. Outputs are
  written atomically (temporary file + rename, :mod:`clpost.atomic`), so a retried or duplicated
  task can never leave a corrupt or half-written frame; existing outputs are skipped (resume).
- A frame whose input is bad (a :class:`~clpost.errors.ClpostError`: deterministic, the
  user's to fix) is reported as the task's *result*, so Dask neither retries it nor logs a
  traceback; the run exits 2 like the serial loop. A task that raises anything else (a crash)
  is retried ``retries`` times; a frame that keeps failing is reported with its error while the
  others continue. A worker that dies is replaced by its nanny and its
  tasks rescheduled by the scheduler (up to ``distributed.scheduler.allowed-failures`` times).

Scaling beyond one machine (SLURM via dask-jobqueue, Kubernetes via dask-kubernetes) only changes
how the scheduler address is obtained; see ``docs/scaling.md``.
"""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .batch import BatchReport, FrameJob, first_size, pending, process_one  # noqa: F401 (first_size: API)
from .camera import Camera
from .errors import ClpostError, InputError


@dataclass(frozen=True)
class PipelineSpec:
    """Everything a worker needs to build the same pipeline as the client (hashable)."""

    camera: Camera
    quality: str = "final"
    stages: tuple[str, ...] | None = None
    device: str | None = None
    display: object = "srgb"
    """How image outputs (-o x.png) and previews are encoded: a clpost encoding name or a
    :class:`clpost.ocio.OcioView` (:mod:`clpost.display_image`)."""
    preview_dir: str | None = None
    """Where each frame's PNG preview goes (``--preview``), None for none."""
    aovs: tuple[str, ...] = ()
    """Diagnostic passes written into each output EXR (``--aovs``, :mod:`clpost.aovs`)."""
    camera_files: bool = False
    """Write each output's effective camera beside it (``--camera-files``, :mod:`clpost.labels.camera_files`)."""


@functools.lru_cache(maxsize=4)
def worker_pipeline(spec: PipelineSpec):
    """The pipeline of this worker process for ``spec``: built on first use, then reused."""
    from .pipeline import Pipeline

    return Pipeline(spec.camera, quality=spec.quality,
                    stages=None if spec.stages is None else list(spec.stages), device=spec.device)


def process_frame_task(spec: PipelineSpec, job: FrameJob, layout: str | None, half: bool,
                       compression: str, overwrite: bool,
                       expect_size: tuple[int, int] | None, sources=None) -> dict:
    """One frame on a worker. Returns what happened (the client aggregates). ``sources``: an
    animated camera (:class:`~clpost.camera_sources.CameraSources`), resolved on the worker."""
    if job.dst.exists() and not overwrite:
        return {"frame": job.frame, "skipped": True, "seconds": 0.0}
    t0 = time.perf_counter()
    try:
        process_one(worker_pipeline(spec), job, layout, half, expect_size, compression, spec.display,
                    None if spec.preview_dir is None else Path(spec.preview_dir), sources, spec.aovs,
                    spec.camera_files)
    except ClpostError as exc:
        # Deterministic and the user's to fix: a result, not an exception Dask would retry.
        return {"frame": job.frame, "skipped": False, "seconds": 0.0, "error": str(exc)}
    return {"frame": job.frame, "skipped": False, "seconds": time.perf_counter() - t0}


def connect(scheduler: str | None = None, workers: int | None = None):
    """A Dask client: to ``scheduler`` if given, else a LocalCluster of ``workers`` processes."""
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as exc:
            raise InputError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({exc}); "
                             "check the address (tcp://HOST:8786) and that it is running") from None
    if not workers or workers < 1:
        raise InputError(f"--workers {workers!r} must be a positive number of worker processes")
    # No dashboard; its HTTP server (health routes) still starts, on a free port: the default
    # 8787 may be another cluster's, which would print a "Port 8787 is already in use" warning.
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           dashboard_address=None, scheduler_kwargs={"dashboard_address": ":0"})
    return Client(cluster)


def _quiet_distributed_logs() -> None:
    import logging

    logging.getLogger("distributed").setLevel(logging.CRITICAL)


def disconnect(client) -> None:
    """Close ``client`` and, if :func:`connect` started it, its LocalCluster.

    Shutting a LocalCluster down races its workers' heartbeats against the closing scheduler;
    a worker that loses the race logs a "Failed to communicate with scheduler" traceback on
    stderr although nothing failed. The run's results are already collected here, so the
    workers, their nannies and this process (which hosts the scheduler) are told to log
    only critical errors before they are closed. A joined cluster (``--scheduler``) is left
    alone: its workers are not ours to quiet.
    """
    cluster = getattr(client, "cluster", None)
    if cluster is not None:
        # on_error="ignore": a dead worker must not keep the others from closing
        client.run(_quiet_distributed_logs, on_error="ignore")
        client.run(_quiet_distributed_logs, nanny=True, on_error="ignore")
        _quiet_distributed_logs()
    client.close()
    if cluster is not None:
        cluster.close()


def process_sequence_dask(client, spec: PipelineSpec, jobs: list[FrameJob], *,
                          layout: str | None = None, overwrite: bool = False, half: bool = False,
                          compression: str = "zip", retries: int = 2,
                          expect_size: tuple[int, int] | None = None,
                          task: Callable = process_frame_task,
                          progress: Callable[[FrameJob, float | None], None] | None = None,
                          on_result: Callable[[int], None] | None = None, sources=None) -> BatchReport:
    """Submit one task per frame and collect results as they complete.

    ``task`` is the per-frame function (tests inject faults through it); ``on_result(n_done)``
    is called after each completed frame (tests use it to kill a worker mid-sequence).
    """
    from distributed import as_completed

    report = BatchReport()
    by_key = {}
    for job in pending(jobs, overwrite, report, progress):
        extra = () if sources is None else (sources,)  # injected test tasks keep their signature
        fut = client.submit(task, spec, job, layout, half, compression, overwrite, expect_size, *extra,
                            key=f"clpost-frame-{job.frame}-{job.dst.name}-{time.time_ns()}",
                            retries=retries, pure=False)
        by_key[fut.key] = (fut, job)
    n = 0
    for fut in as_completed([f for f, _ in by_key.values()]):
        job = by_key[fut.key][1]
        if fut.status == "finished":
            res = fut.result()
            if res.get("error"):
                msg = res["error"]
                report.failed[job.frame] = msg if str(job.src) in msg else f"{job.src}: {msg}"
                report.user_errors.append(job.frame)
                if progress:
                    progress(job, float("nan"))
            elif res["skipped"]:
                report.skipped.append(job.frame)
                if progress:
                    progress(job, None)
            else:
                report.done.append(job.frame)
                report.seconds.append(res["seconds"])
                if progress:
                    progress(job, res["seconds"])
        else:
            exc = fut.exception()
            report.failed[job.frame] = f"{job.src}: {exc}"
            if progress:
                progress(job, float("nan"))
        n += 1
        if on_result:
            on_result(n)
    report.done.sort()
    return report






# -- long exposure as a tree reduction ------------------------------------------------------------

def expose_chunk(pattern: str, items: list, fps, layout: str | None, device: str | None, setup=None):
    """Accumulate one run of frames ``items`` = [(frame, seconds), …] on a worker; returns the
    :class:`~clpost.expose.ExposurePartial` (host float64 sums, exact weights). ``setup``: a
    :class:`~clpost.expose.CameraSetup` — each frame goes through its per-frame optics first."""
    from . import exr
    from .expose import CameraAccumulator, ExposureAccumulator
    from .sequence import expand

    acc = None
    try:
        if setup is not None:
            from .batch import read_input
            from .pipeline import Pipeline

            cam_acc, reader = CameraAccumulator(setup), Pipeline(setup.camera)
            for n, seconds in items:
                cam_acc.add(read_input(reader, Path(expand(pattern, n)), layout), n, seconds)
            return cam_acc.partial()
        for n, seconds in items:
            path = expand(pattern, n)
            frame = exr.read_frame(path, layout)
            if acc is None:
                acc = ExposureAccumulator(frame.size, fps, device)
            try:
                acc.add(frame.color, seconds)
            except InputError as exc:
                raise InputError(f"{path}: {exc}") from None
    except ClpostError as exc:
        return UserFailure(str(exc))  # not retried: the input is bad
    return acc.partial()


@dataclass(frozen=True)
class UserFailure:
    """A task result standing for a user error (bad input), passed up the reduction tree."""

    message: str


def combine_partials(a, b):
    """One node of the reduction tree (associative: weights exact, sums in float64)."""
    if isinstance(a, UserFailure):
        return a
    if isinstance(b, UserFailure):
        return b
    return a.combine(b)


def expose_dask(client, pattern: str, frames, fps, t_open, t_close, *, layout: str | None = None,
                device: str | None = None, chunk: int = 8, retries: int = 2, first: int = 0, setup=None):
    """``clpost expose`` on a cluster: chunks of ``chunk`` consecutive frames are accumulated on
    workers, then the partial exposures are combined pairwise in a tree (log₂ depth), so no
    worker holds more than two partials. Same result as the serial accumulation to float32
    rounding of each chunk's compensated sum (tested to 1e-6). ``first``: the time origin
    (:func:`clpost.expose.frame_interval`); ``setup``: a :class:`~clpost.expose.CameraSetup` whose
    per-frame optics each worker applies (:func:`clpost.expose.finish` completes the exposure)."""
    from .expose import exposure_plan

    plan = exposure_plan(frames, fps, t_open, t_close, first)
    if not plan:
        raise InputError("no frame lies inside the shutter interval")
    if chunk < 1:
        raise InputError(f"chunk={chunk!r} must be >= 1 frame")
    futs = [client.submit(expose_chunk, pattern, plan[i:i + chunk], fps, layout, device, setup,
                          retries=retries, pure=False)
            for i in range(0, len(plan), chunk)]
    while len(futs) > 1:
        paired = [client.submit(combine_partials, a, b, retries=retries, pure=False)
                  for a, b in zip(futs[::2], futs[1::2])]
        if len(futs) % 2:
            paired.append(futs[-1])
        futs = paired
    out = futs[0].result()
    if isinstance(out, UserFailure):
        raise InputError(out.message)
    return out
