"""Kill/resume soak: `clpost process` killed with SIGKILL or SIGTERM at random points, resumed, and
checked frame by frame against an uninterrupted run.

Each cycle starts `clpost process` (serial, or `--workers 2` every ``--workers-every``-th cycle)
on the same input sequence and output folder and kills it after a random delay: SIGKILL to the
whole process group (the job is gone, nothing can clean up), or SIGTERM to the main process (what
`kill PID` and batch schedulers send). After every kill:

- every output frame that exists under its final name is bit-identical to the reference run
  (never half-written, never another run's);
- after a SIGTERM of a serial run, no new temporary file and no lock file is left;
- anything else in the folder is one of clpost's own temporary or lock files (a SIGKILL's), which
  the next run must remove.

When a run finishes by itself the folder is emptied so later kills land mid-sequence again. At the
end a last run completes the sequence: every frame must be bit-identical to the reference and the
folder must hold nothing else. Exit status 0 when all held; a summary line per cycle and a final
JSON line.

    python tools/soak.py --cycles 60 --workers-every 4
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from clpost import Frame, exr  # noqa: E402

CAM = ["--f-number", "2.8", "--shutter", "1/60", "--iso", "200", "--luminance-scale", "50", "--fps", "24",
       "--compression", "piz", "--quiet"]
FRAME_RE = re.compile(r"^o\.\d{4}\.exr$")
OURS_RE = re.compile(r"^\.o\.(\d{4}\.exr\.tmp-[a-z0-9_]{8}\.exr|####\.exr\.lock)$")


def make_inputs(folder: Path, n: int, w: int, h: int) -> None:
    rng = np.random.default_rng(7)
    for i in range(1, n + 1):
        f = Frame((rng.random((h, w, 3)) * 4).astype(np.float32), depth=rng.uniform(1, 30, (h, w)).astype(np.float32),
                  velocity=rng.normal(scale=3, size=(h, w, 2)).astype(np.float32))
        exr.write_frame(folder / f"in.{i:04d}.exr", f)


def digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def command(folder: Path, out: str, workers: bool) -> list[str]:
    return [sys.executable, "-m", "clpost.cli", "process", str(folder / "in.####.exr"), "-o", out, *CAM,
            *(["--workers", "2"] if workers else [])]


def run(cmd, env, kill_after: float | None, sig: int):
    """Run ``cmd`` in its own session; kill it after ``kill_after`` s. Returns (exit code, stderr, killed)."""
    p = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    killed = False
    try:
        _, err = p.communicate(timeout=kill_after)
    except BaseException as exc:
        if not isinstance(exc, subprocess.TimeoutExpired):  # the soak itself is stopped: no orphans
            os.killpg(p.pid, signal.SIGKILL)
            raise
        killed = True
        if sig == signal.SIGKILL:
            os.killpg(p.pid, signal.SIGKILL)
        else:
            p.send_signal(sig)
        try:
            _, err = p.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            _, err = p.communicate()
    # Whatever the main process left (Dask nannies/workers), gone before the next cycle.
    for _ in range(100):
        try:
            os.killpg(p.pid, 0)
        except ProcessLookupError:
            break
        if _ > 50:
            os.killpg(p.pid, signal.SIGKILL)
        time.sleep(0.1)
    return p.returncode, err, killed


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=60)
    ap.add_argument("--workers-every", type=int, default=4, help="every Nth cycle runs --workers 2 (0: never)")
    ap.add_argument("--frames", type=int, default=6)
    ap.add_argument("--size", default="480x270")
    ap.add_argument("--seed", type=int, default=17)
    ap.add_argument("--keep", action="store_true", help="keep the work folder")
    args = ap.parse_args(argv)
    rng = random.Random(args.seed)
    w, h = map(int, args.size.split("x"))
    work = Path(tempfile.mkdtemp(prefix="clpost-soak-"))
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    make_inputs(work, args.frames, w, h)
    inputs = {p.name: digest(p) for p in work.glob("in.*.exr")}

    t0 = time.monotonic()
    code, err, _ = run(command(work, str(work / "ref" / "o.####.exr"), False), env, None, 0)
    t_serial = time.monotonic() - t0
    if code != 0:
        print(f"reference run failed: {err}", file=sys.stderr)
        return 1
    ref = {p.name: digest(p) for p in (work / "ref").glob("o.*.exr")}
    t_workers = None
    out = work / "out"
    failures: list[str] = []
    counts = {"SIGKILL": 0, "SIGTERM": 0, "finished": 0, "serial": 0, "workers": 0}
    for cycle in range(1, args.cycles + 1):
        workers = bool(args.workers_every) and cycle % args.workers_every == 0
        if workers and t_workers is None:
            t1 = time.monotonic()
            run(command(work, str(work / "wref" / "o.####.exr"), True), env, None, 0)
            t_workers = time.monotonic() - t1
            wref = {p.name: digest(p) for p in (work / "wref").glob("o.*.exr")}
            if wref != ref:
                failures.append("the --workers 2 run differs from the serial reference")
        span = t_workers if workers else t_serial
        sig = rng.choice([signal.SIGKILL, signal.SIGTERM])
        delay = rng.uniform(0.2, span * 1.05)
        before = set(os.listdir(out)) if out.exists() else set()
        code, err, killed = run(command(work, str(out / "o.####.exr"), workers), env, delay, sig)
        name = signal.Signals(sig).name if killed else "finished"
        counts[name] += 1
        counts["workers" if workers else "serial"] += 1
        names = sorted(os.listdir(out)) if out.exists() else []
        frames = [n for n in names if FRAME_RE.match(n)]
        others = [n for n in names if not FRAME_RE.match(n)]
        bad = [n for n in frames if digest(out / n) != ref[n]]
        problems = []
        if bad:
            problems.append(f"frames differ from the reference: {bad}")
        if [n for n in others if not OURS_RE.match(n)]:
            problems.append(f"foreign files: {others}")
        # (A SIGTERM during start-up, before the handler exists, kills the run before it touched
        # anything: an earlier SIGKILL's leftovers may still be there, but nothing new.)
        if killed and sig == signal.SIGTERM and not workers and set(others) - before:
            problems.append(f"SIGTERM left {sorted(set(others) - before)}")
        if "Traceback" in err:
            problems.append("traceback: " + err.strip().splitlines()[-1])
        if not killed and code != 0:
            problems.append(f"exit {code}: {err.strip()[-300:]}")
        line = (f"cycle {cycle:3d} {'workers' if workers else 'serial '} {name:8s} after {delay:5.2f} s: "
                f"{len(frames)} frame(s), {len(others)} leftover(s) {others if others else ''}"
                + (f" PROBLEM {problems}" if problems else ""))
        print(line, flush=True)
        failures.extend(f"cycle {cycle}: {p}" for p in problems)
        if not killed:
            shutil.rmtree(out)  # start over so that later kills land mid-sequence
    # Resume to completion: bit-identical, nothing else.
    code, err, _ = run(command(work, str(out / "o.####.exr"), False), env, None, 0)
    names = sorted(os.listdir(out))
    final = {n: digest(out / n) for n in names if FRAME_RE.match(n)}
    if code != 0:
        failures.append(f"final resume exited {code}: {err.strip()[-300:]}")
    if final != ref:
        failures.append(f"final frames differ: {sorted(set(final) ^ set(ref))} or contents")
    if names != sorted(ref):
        failures.append(f"stray files after the final run: {sorted(set(names) - set(ref))}")
    if {p.name: digest(p) for p in work.glob("in.*.exr")} != inputs:
        failures.append("inputs changed")
    summary = {"cycles": args.cycles, **counts, "frames": args.frames, "size": args.size,
               "uninterrupted_s": {"serial": round(t_serial, 2), "workers": t_workers and round(t_workers, 2)},
               "final_bit_identical": final == ref, "stray_files": sorted(set(names) - set(ref)),
               "failures": failures}
    print(json.dumps(summary))
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
