"""Bad input never destroys, mixes or half-writes frames; every error is one line naming the file
or parameter and the fix; nothing is created or changed.

The matrix runs ``python -m clpost.cli`` in a subprocess per case (as a user would) and checks:
exit status, at most 3 stderr lines, no traceback, the message names the file/parameter and the
fix, and the case's folder is byte-for-byte unchanged (hash of every file, listing included).
``CLPOST_MATRIX_REPORT=<file>`` appends one JSON row per case (``tools/reliability_matrix.py``
turns them into ``docs/reliability.md``).
"""
from __future__ import annotations

import hashlib
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from clpost import Frame, Pipeline, exr
from clpost.atomic import atomic_path, remove_stale_temps
from clpost.errors import InputError
from clpost.outputs import OutputLock, check_paths

ROOT = Path(__file__).resolve().parents[1]
CAM = ["--f-number", "2.8", "--shutter", "1/60", "--iso", "200", "--luminance-scale", "50"]


def clpost(*args, cwd: Path, timeout: float = 120, env_extra: dict | None = None):
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.update(env_extra or {})
    r = subprocess.run([sys.executable, "-m", "clpost.cli", *map(str, args)], cwd=cwd, env=env,
                       capture_output=True, text=True, timeout=timeout)
    return r.returncode, r.stdout, r.stderr


def snapshot(folder: Path) -> dict[str, str]:
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        if p.is_symlink():
            out[rel] = "-> " + os.readlink(p)
        elif p.is_file():
            out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
        else:
            out[rel] = "dir"
    return out


def frame(w=16, h=12, seed=0, depth=True, velocity=True, value=None) -> Frame:
    rng = np.random.default_rng(seed)
    color = rng.random((h, w, 3)).astype(np.float32) if value is None else np.full((h, w, 3), value, np.float32)
    return Frame(color, depth=rng.uniform(1, 20, (h, w)).astype(np.float32) if depth else None,
                 velocity=rng.normal(size=(h, w, 2)).astype(np.float32) if velocity else None)


def patch_window(path: Path, name: bytes, box: tuple[int, int, int, int]) -> None:
    """Rewrite the box2i attribute ``name`` (dataWindow/displayWindow) of every part's header."""
    b = bytearray(path.read_bytes())
    key = name + b"\0box2i\0" + struct.pack("<i", 16)
    i = b.find(key)
    assert i > 0
    while i > 0:
        b[i + len(key):i + len(key) + 16] = struct.pack("<4i", *box)
        i = b.find(key, i + 1)
    path.write_bytes(bytes(b))


# -- the cases ---------------------------------------------------------------------------------

def _seq(d: Path, n=3, **kw):
    for i in range(1, n + 1):
        exr.write_frame(d / f"in.{i:04d}.exr", frame(seed=i, **kw))


def setup_single(d):
    exr.write_frame(d / "x.exr", frame(value=0.18))


def setup_symlink(d):
    setup_single(d)
    os.symlink("x.exr", d / "link.exr")


def setup_seq(d):
    _seq(d)


def setup_front(d, alpha=True, n=2, size=(16, 12)):
    """in.0001-0003.exr and a front layer fg.0001..n.exr: a square over a transparent film."""
    _seq(d)
    w, h = size
    for i in range(1, n + 1):
        a = np.zeros((h, w), np.float32)
        a[3:8, 4:10] = 1
        fg = Frame(np.full((h, w, 3), 0.5, np.float32) * a[..., None], alpha=a if alpha else None,
                   depth=np.where(a > 0, np.float32(0.5), np.float32(np.inf)).astype(np.float32))
        exr.write_frame(d / f"fg.{i:04d}.exr", fg)


def setup_huge_display(d):
    exr.write_frame(d / "big.exr", frame(8, 8, depth=False, velocity=False))
    patch_window(d / "big.exr", b"displayWindow", (0, 0, 59999, 59999))


def setup_huge_data(d):
    exr.write_frame(d / "big.exr", frame(8, 8, depth=False, velocity=False))
    patch_window(d / "big.exr", b"dataWindow", (0, 0, 99999, 99999))
    patch_window(d / "big.exr", b"displayWindow", (0, 0, 99999, 99999))


def setup_truncated(d):
    exr.write_frame(d / "t.exr", frame(64, 48))
    data = (d / "t.exr").read_bytes()
    (d / "t.exr").write_bytes(data[:len(data) * 2 // 3])


def setup_no_depth(d):
    exr.write_frame(d / "x.exr", frame(depth=False))


def setup_seq_velocity_gap(d):
    for i in range(1, 4):
        exr.write_frame(d / f"in.{i:04d}.exr", frame(seed=i, velocity=(i != 3)))


def setup_expose_sizes(d):
    for i in range(0, 3):
        exr.write_frame(d / f"in.{i:04d}.exr", frame(16 if i != 2 else 20, 12, seed=i))


def setup_bad_yaml(d):
    setup_single(d)
    (d / "cal.yaml").write_text("camera_matrix: [1, 2\nwidth: {\n")


def setup_bad_frame_seq(d):
    _seq(d, n=4)
    (d / "in.0003.exr").write_bytes(b"\x76\x2f\x31\x01 definitely not an exr")


def setup_live_lock(d):
    _seq(d, n=2)
    (d / "out").mkdir()
    # A lock held by a live process on this host (pytest itself; its start time recorded).
    from clpost.outputs import _proc_start

    (d / "out" / ".o.####.exr.lock").write_text(json.dumps({
        "pid": os.getpid(), "host": socket.gethostname(), "proc_start": _proc_start(os.getpid()),
        "started": "2026-01-01T00:00:00", "output": "out/o.####.exr"}))


# id: (setup, argv, expected exit, strings the message must hold (file/parameter and fix))
CASES = {
    "output is the input": (setup_single, ["process", "x.exr", "-o", "x.exr", *CAM], 2,
                            ["x.exr", "destroy", "x_post.exr"]),
    "output is the input, --overwrite": (setup_single, ["process", "x.exr", "-o", "x.exr", "--overwrite", *CAM], 2,
                                         ["x.exr", "destroy", "--overwrite does not change"]),
    "output is the input via ./ and absolute": (setup_single, ["process", "./x.exr", "-o", "{d}/x.exr", *CAM], 2,
                                                ["x.exr", "destroy"]),
    "output is a symlink to the input": (setup_symlink, ["process", "x.exr", "-o", "link.exr", "--overwrite", *CAM], 2,
                                         ["link.exr", "destroy"]),
    "sequence output pattern = input pattern": (setup_seq, ["process", "in.####.exr", "-o", "in.####.exr", *CAM], 2,
                                                ["in.0001.exr", "destroy", "-o"]),
    "sequence output as another spelling of the input": (
        setup_seq, ["process", "in.####.exr", "-o", "in.%04d.exr", "--overwrite", *CAM], 2, ["in.%04d.exr", "destroy"]),
    "expose -o names one of its inputs": (
        setup_seq, ["expose", "in.####.exr", "-o", "in.0002.exr", "--open", "0", "--close", "0.1", "--fps", "24",
                    "--overwrite"], 2, ["in.0002.exr", "destroy"]),
    "input is a directory": (setup_single, ["process", ".", "-o", "y.exr", *CAM], 2, ["is a directory", "pattern"]),
    "info on a directory": (setup_single, ["info", "."], 2, ["is a directory"]),
    "input missing": (setup_single, ["process", "nope.exr", "-o", "y.exr", *CAM], 2, ["nope.exr", "does not exist"]),
    "60000² display window, 8×8 data (process)": (setup_huge_display, ["process", "big.exr", "-o", "y.exr", *CAM], 2,
                                                   ["big.exr", "GiB", "60000x60000"]),
    "60000² display window, 8×8 data (info)": (setup_huge_display, ["info", "big.exr"], 2, ["big.exr", "GiB"]),
    "100000² data window (process)": (setup_huge_data, ["process", "big.exr", "-o", "y.exr", *CAM], 2,
                                      ["big.exr", "100000x100000", "window"]),
    "100000² data window (info)": (setup_huge_data, ["info", "big.exr"], 2, ["big.exr", "100000x100000"]),
    "truncated EXR (no OpenEXR chatter)": (setup_truncated, ["process", "t.exr", "-o", "y.exr", *CAM], 2,
                                           ["t.exr", "corrupt or truncated", "re-render"]),
    "truncated EXR (info)": (setup_truncated, ["info", "t.exr"], 2, ["t.exr", "re-render"]),
    "--workers 0": (setup_seq, ["process", "in.####.exr", "-o", "o.####.exr", "--workers", "0", *CAM], 2,
                    ["--workers", "1 or more", "--help"]),
    "--retries -1": (setup_seq, ["process", "in.####.exr", "-o", "o.####.exr", "--retries", "-1", *CAM], 2,
                     ["--retries", "0 or more"]),
    "--stages ,": (setup_seq, ["process", "in.####.exr", "-o", "o.####.exr", "--stages", ",", *CAM], 2,
                   ["--stages", "names no stage", "leave --stages out"]),
    "--frames ''": (setup_seq, ["process", "in.####.exr", "-o", "o.####.exr", "--frames", "", *CAM], 2,
                    ["--frames", "1-100"]),
    "unknown option": (setup_single, ["process", "x.exr", "-o", "y.exr", "--focal", "50"], 2,
                       ["--focal", "--help"]),
    "--calibration file missing": (setup_single, ["process", "x.exr", "-o", "y.exr", "--calibration", "no.yaml"], 2,
                                   ["--calibration", "no.yaml"]),
    "--calibration malformed YAML": (setup_bad_yaml, ["process", "x.exr", "-o", "y.exr", "--calibration", "cal.yaml"],
                                     2, ["cal.yaml", "line 1", "--help"]),
    "DoF without depth": (setup_no_depth, ["process", "x.exr", "-o", "y.exr", "--depth-of-field", "on", *CAM], 2,
                          ["x.exr", "depth", "--depth-of-field off"]),
    "velocity missing in frame 3 of a sequence": (
        setup_seq_velocity_gap, ["process", "in.####.exr", "-o", "{d}/out/o.####.exr", "--fps", "24", "--quiet", *CAM],
        2, ["in.0003.exr", "velocity", "--fps"]),
    "expose with a size change": (
        setup_expose_sizes, ["expose", "in.####.exr", "-o", "{d}/out/e.exr", "--open", "0", "--close", "3/24",
                             "--fps", "24", "--quiet"], 2, ["in.0002.exr", "20x12", "--frames"]),
    "--front missing for frame 3": (setup_front, ["process", "in.####.exr", "-o", "out/o.####.exr", "--front",
                                                  "fg.####.exr", *CAM], 2, ["fg.0003.exr", "does not exist", "--frames"]),
    "--front without alpha": (lambda d: setup_front(d, alpha=False, n=3),
                              ["process", "in.####.exr", "-o", "out/o.####.exr", "--front", "fg.####.exr", *CAM], 2,
                              ["fg.0001.exr", "no alpha channel", "Film > Transparent"]),
    "--front at another size": (lambda d: setup_front(d, n=3, size=(20, 12)),
                                ["process", "in.####.exr", "-o", "out/o.####.exr", "--front", "fg.####.exr", *CAM], 2,
                                ["fg.0001.exr", "20x12", "16x12", "one resolution"]),
    "--front is the input": (setup_front, ["process", "in.####.exr", "-o", "out/o.####.exr", "--front", "in.####.exr",
                                           *CAM], 2, ["--front", "is the input", "fg.####.exr"]),
    "--front with --stages leaving out front_layer": (
        lambda d: setup_front(d, n=3), ["process", "in.####.exr", "-o", "out/o.####.exr", "--front", "fg.####.exr",
                                        "--stages", "exposure", *CAM], 2, ["in.0001.exr", "add front_layer to --stages"]),
    "second writer into a locked output sequence": (
        setup_live_lock, ["process", "in.####.exr", "-o", "out/o.####.exr", "--quiet", *CAM], 2,
        ["out/o.####.exr", f"pid {os.getpid()}", "wait for it"]),
}

# Cases that write frames before the failing one: the folder changes only by those outputs.
PARTIAL_OUTPUT_OK = {"velocity missing in frame 3 of a sequence": {"out", "out/o.0001.exr", "out/o.0002.exr"}}


def _report(row: dict) -> None:
    path = os.environ.get("CLPOST_MATRIX_REPORT")
    if path:
        with open(path, "a") as f:
            f.write(json.dumps(row) + "\n")


@pytest.mark.parametrize("case", list(CASES))
def test_bad_input_matrix(case, tmp_path):
    setup, argv, want_code, must = CASES[case]
    d = tmp_path / "case"
    d.mkdir()
    setup(d)
    before = snapshot(d)
    argv = [a.replace("{d}", str(d)) for a in argv]
    code, out, err = clpost(*argv, cwd=d)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    after = snapshot(d)
    changed = {k for k in set(before) | set(after) if before.get(k) != after.get(k)}
    ok = (code == want_code and len(lines) <= 3 and "Traceback" not in err
          and all(m in err for m in must) and changed <= PARTIAL_OUTPUT_OK.get(case, set()))
    _report({"case": case, "command": "clpost " + " ".join(a.replace(str(d) + "/", "") for a in argv),
             "exit": code, "lines": len(lines), "verdict": "held" if ok else "FAILED",
             "message": (lines[-1] if lines else "").replace(str(d) + "/", "").replace(str(d), ".")})
    assert code == want_code, err
    assert len(lines) <= 3, err
    assert "Traceback" not in err and "Exception raised" not in out  # nor OpenEXR's chatter on stdout
    for m in must:
        assert m in err, f"{m!r} not in {err!r}"
    assert changed <= PARTIAL_OUTPUT_OK.get(case, set()), f"changed: {sorted(changed)}"


def test_bad_frame_under_workers_is_one_line_exit_2_not_retried(tmp_path):
    d = tmp_path / "case"
    d.mkdir()
    setup_bad_frame_seq(d)
    inputs = {k: v for k, v in snapshot(d).items()}
    code, out, err = clpost("process", "in.####.exr", "-o", "out/o.####.exr", "--workers", "2", "--retries", "3",
                            "--quiet", *CAM, cwd=d, timeout=240)
    lines = [ln for ln in err.splitlines() if ln.strip() and "distributed." not in ln]
    _report({"case": "bad frame under --workers 2", "command": "clpost process in.####.exr -o out/o.####.exr "
             "--workers 2 --retries 3", "exit": code, "lines": len(lines),
             "verdict": "held" if code == 2 and len(lines) <= 3 else "FAILED",
             "message": (lines[0] if lines else "").replace(str(d) + "/", "")})
    assert code == 2, err
    assert "Traceback" not in err and "Compute Failed" not in err, err
    assert "frame 3 failed" in err and "in.0003.exr" in err, err
    assert len(lines) <= 3, err
    after = snapshot(d)
    assert {k: after[k] for k in inputs} == inputs
    assert sorted(k for k in after if k.startswith("out/")) == ["out/o.0001.exr", "out/o.0002.exr",
                                                                 "out/o.0004.exr"], (sorted(after), err)


# -- the pieces, as a library -----------------------------------------------------------------

def test_frame_keeps_its_own_copy_of_caller_arrays():
    color = np.full((4, 5, 3), 0.5, np.float32)
    depth = np.full((4, 5), 2.0, np.float32)
    f = Frame(color, depth=depth)
    color[0, 0, 0] = np.nan
    depth[0, 0] = -1
    assert np.isfinite(f.color).all() and (f.depth > 0).all()
    out = Pipeline(__import__("clpost").Camera()).run(f)
    assert np.isfinite(out.color).all()


def test_pipeline_run_of_an_array_says_what_to_pass():
    with pytest.raises(InputError, match=r"Pipeline.run takes a clpost.Frame.*Frame\(color=\.\.\.\)"):
        Pipeline(__import__("clpost").Camera()).run(np.zeros((4, 4, 3), np.float32))


def test_check_paths_refuses_same_inode_under_another_name(tmp_path):
    exr.write_frame(tmp_path / "a.exr", frame())
    os.link(tmp_path / "a.exr", tmp_path / "b.exr")
    with pytest.raises(InputError, match="b.exr is the input"):
        check_paths([(tmp_path / "a.exr", tmp_path / "b.exr")])
    check_paths([(tmp_path / "a.exr", tmp_path / "c.exr")])


def test_stale_temp_files_of_our_pattern_are_removed_and_nothing_else(tmp_path):
    out = tmp_path / "o.0004.exr"
    ours = tmp_path / ".o.0004.exr.tmp-ab_cd123.exr"
    other_frame = tmp_path / ".o.0005.exr.tmp-ab_cd123.exr"
    user = [tmp_path / ".o.0004.exr.tmp-notours", tmp_path / "o.0004.exr.tmp-ab_cd123.exr",
            tmp_path / ".o.0004.exr.tmp-ab_cd123.exr.bak"]
    for p in [ours, other_frame, *user]:
        p.write_bytes(b"x")
    assert remove_stale_temps([out]) == [ours]
    assert not ours.exists() and other_frame.exists() and all(p.exists() for p in user)


def test_a_temp_file_being_written_is_not_stale(tmp_path):
    out = tmp_path / "o.exr"
    with atomic_path(out) as tmp:
        tmp.write_bytes(b"half")
        assert remove_stale_temps([out]) == []
        assert tmp.exists()
    assert out.read_bytes() == b"half"


def test_lock_refuses_a_live_holder_and_takes_over_a_dead_one(tmp_path):
    target = tmp_path / "o.####.exr"
    with OutputLock(target) as lock:
        assert json.loads(lock.path.read_text())["pid"] == os.getpid()
        # Another holder that is alive: refused, naming it.
        child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
        try:
            lock.path.write_text(json.dumps({"pid": child.pid, "host": socket.gethostname(), "proc_start": None,
                                             "started": "t0", "output": str(target)}))
            with pytest.raises(InputError, match=f"pid {child.pid}"):
                OutputLock(target).acquire()
        finally:
            child.kill()
            child.wait()
        # The same holder, dead now (SIGKILL): its lock is taken over.
        second = OutputLock(target)
        second.acquire()
        assert json.loads(second.path.read_text())["pid"] == os.getpid()
        second.release()
    assert not lock.path.exists()


def test_sigterm_mid_sequence_leaves_no_temp_and_a_rerun_completes(tmp_path):
    for i in range(1, 7):
        exr.write_frame(tmp_path / f"in.{i:04d}.exr", frame(320, 240, seed=i))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "clpost.cli", "process", "in.####.exr", "-o", "out/o.####.exr", "--compression",
           "piz", *CAM]
    p = subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list((tmp_path / "out").glob("o.*.exr")):
        time.sleep(0.02)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode in (0, 143), err
    assert "Traceback" not in err
    names = sorted(x.name for x in (tmp_path / "out").iterdir())
    assert all(n.startswith("o.") and n.endswith(".exr") for n in names), names  # no temp, no lock
    r = subprocess.run(cmd + ["--quiet"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert sorted(x.name for x in (tmp_path / "out").iterdir()) == [f"o.{i:04d}.exr" for i in range(1, 7)]


def test_two_concurrent_runs_into_one_output_never_mix_frames(tmp_path):
    for i in range(1, 5):
        exr.write_frame(tmp_path / f"in.{i:04d}.exr", frame(160, 90, seed=i))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    base = [sys.executable, "-m", "clpost.cli", "process", "in.####.exr", "-o", "out/o.####.exr", "--quiet",
            "--shutter", "1/60", "--iso", "200", "--luminance-scale", "50"]
    runs = [subprocess.Popen(base + ["--f-number", fn], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True) for fn in ("2.8", "8")]
    results = [(p.wait(timeout=180), *p.communicate()) for p in runs]
    fnumbers = {exr.read_frame(p).metadata["header"]["clpost.fNumber"] for p in (tmp_path / "out").glob("o.*.exr")}
    assert len(fnumbers) == 1, f"frames of both runs mixed: {fnumbers}"
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [f"o.{i:04d}.exr" for i in range(1, 5)]
    for code, out, err in results:
        assert "Traceback" not in err
        # Either refused while the other held the lock (naming it), or done / all skipped after it.
        assert (code == 2 and "another clpost run (pid" in err) or code == 0, err
