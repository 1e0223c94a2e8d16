"""EXR fuzzing: damaged files written in each renderer's layout never crash clpost.

Small real files in the clpost, Blender (multi-part), Nuke and Arnold layouts are mutated
(truncations, flipped header bytes, flipped pixel bytes, absurd data/display windows, absurd
channel lists) and fed to ``clpost info`` and ``clpost process`` through ``clpost.cli.main`` in one
subprocess whose address space is capped with ``RLIMIT_AS``; every run must end in exit 0 (the
mutation was harmless) or 2 with at most 3 lines on stderr (file descriptor 2, so OpenEXR's own
messages count), no traceback and no output file. A crash (segfault, MemoryError escaping,
exit 1) fails the test. Bounded in time: ``CLPOST_FUZZ_SECONDS`` (default 20) of mutations.
"""
from __future__ import annotations

import json
import os
import random
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np

from clpost import Frame, exr

ROOT = Path(__file__).resolve().parents[1]
SECONDS = float(os.environ.get("CLPOST_FUZZ_SECONDS", "20"))

DRIVER = r'''
import json, os, resource, sys, tempfile, time
import clpost.cli as cli
files, budget, out_dir = json.loads(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
# Warm up (imports, OpenCL) before capping the address space: the cap is for the reads.
cli.main(["process", files[0]["path"], "-o", os.path.join(out_dir, "warm.exr"), "--quiet"])
os.unlink(os.path.join(out_dir, "warm.exr"))
with open("/proc/self/status") as f:
    vm = [int(l.split()[1]) * 1024 for l in f if l.startswith("VmSize:")][0]
cap = vm + (1 << 30)
resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
t_end = time.monotonic() + budget
results = []
for i, item in enumerate(files):
    if time.monotonic() > t_end:
        break
    for cmd in ("info", "process"):
        out = os.path.join(out_dir, f"o{i}.exr")
        argv = ["info", item["path"]] if cmd == "info" else ["process", item["path"], "-o", out, "--quiet"]
        with tempfile.TemporaryFile() as cap_out, tempfile.TemporaryFile() as cap_err:
            sys.stdout.flush()
            sys.stderr.flush()
            saved = os.dup(1), os.dup(2)
            os.dup2(cap_out.fileno(), 1)
            os.dup2(cap_err.fileno(), 2)
            try:
                code = cli.main(argv)
            except SystemExit as e:
                code = e.code
            except BaseException as e:
                import traceback
                traceback.print_exc()
                code = 1
            finally:
                sys.stdout.flush()
                sys.stderr.flush()
                os.dup2(saved[0], 1)
                os.dup2(saved[1], 2)
                os.close(saved[0])
                os.close(saved[1])
            cap_out.seek(0)
            cap_err.seek(0)
            stdout = cap_out.read().decode("utf-8", "replace")
            err = cap_err.read().decode("utf-8", "replace")
        results.append({"file": item["path"], "mutation": item["mutation"], "cmd": cmd, "code": code,
                        "err": err, "chatter": "Exception" in stdout or "Warning" in stdout,
                        "output": os.path.exists(out)})
        if os.path.exists(out):
            os.unlink(out)
print(json.dumps({"cap": cap, "results": results}))
'''


def _frame(w, h, seed):
    rng = np.random.default_rng(seed)
    return Frame(rng.random((h, w, 3)).astype(np.float32) * 2, depth=rng.uniform(1, 9, (h, w)).astype(np.float32),
                 velocity=rng.normal(size=(h, w, 2)).astype(np.float32), alpha=rng.random((h, w)).astype(np.float32))


def _header_end(data: bytes) -> int:
    """Offset just past the headers (where the chunk offset table starts)."""
    from clpost.exr.io import _Reader

    parts = _Reader(data, Path("x"))
    parts.i = 8
    multipart = struct.unpack("<i", data[4:8])[0] & 0x1000
    while True:
        while parts.name(255):
            parts.name(255)
            parts.take(parts.int32())
        if not multipart or data[parts.i:parts.i + 1] == b"\0":
            return parts.i + (1 if multipart else 0)


def _set_box(data: bytearray, name: bytes, box) -> bytearray:
    key = name + b"\0box2i\0" + struct.pack("<i", 16)
    i = data.find(key)
    while i >= 0:
        data[i + len(key):i + len(key) + 16] = struct.pack("<4i", *box)
        i = data.find(key, i + 1)
    return data


def mutations(base: bytes, rng: random.Random):
    """(name, bytes) mutations of one file."""
    hend = _header_end(base)
    n = len(base)
    yield "truncated at header", base[:rng.randrange(1, hend)]
    yield "truncated in pixels", base[:rng.randrange(hend, n)]
    b = bytearray(base)
    for _ in range(rng.randint(1, 4)):
        b[rng.randrange(8, hend)] ^= 1 << rng.randrange(8)
    yield "flipped header bits", bytes(b)
    b = bytearray(base)
    for _ in range(rng.randint(1, 8)):
        b[rng.randrange(hend, n)] ^= 0xFF
    yield "flipped pixel/offset bytes", bytes(b)
    big = rng.choice([60000, 100000, 1 << 20, 2**31 - 1])
    yield "absurd display window", bytes(_set_box(bytearray(base), b"displayWindow", (0, 0, big, big)))
    yield "absurd data window", bytes(_set_box(bytearray(base), b"dataWindow", (0, 0, big, 7)))
    yield "inverted data window", bytes(_set_box(bytearray(base), b"dataWindow", (5, 5, -big, 2)))
    b = bytearray(base)
    key = b"channels\0chlist\0"
    i = b.find(key)
    b[i + len(key):i + len(key) + 4] = struct.pack("<i", rng.choice([2**31 - 1, 10**6, 0, -1]))
    yield "absurd channel list size", bytes(b)
    # A channel list of 5000 channels (same header otherwise): many channels, tiny file.
    chans = b"".join(f"c{k}".encode() + b"\0" + struct.pack("<iB3xii", 2, 0, 1, 1) for k in range(5000)) + b"\0"
    size = struct.unpack("<i", base[i + len(key):i + len(key) + 4])[0]
    yield "5000 channels", base[:i + len(key)] + struct.pack("<i", len(chans)) + chans + base[i + len(key) + 4 + size:]


def test_damaged_exrs_of_every_layout_fail_cleanly(tmp_path):
    rng = random.Random(17)
    files = []
    for layout in exr.LAYOUTS:
        for comp in ("zip", "piz", "none"):
            src = tmp_path / f"{layout}_{comp}.exr"
            exr.write_frame(src, _frame(24, 16, len(files)), layout=layout, compression=comp,
                            focal_px=30.0 if layout == "arnold" else None)
            files.append({"path": str(src), "mutation": "none (original)"})
    originals = list(files)
    k = 0
    for _ in range(3):
        for item in originals:
            for name, data in mutations(Path(item["path"]).read_bytes(), rng):
                p = tmp_path / f"m{k:04d}_{Path(item['path']).stem}.exr"
                p.write_bytes(data)
                files.append({"path": str(p), "mutation": f"{name} ({Path(item['path']).stem})"})
                k += 1
    # Originals first (they must be read), then the mutations in a shuffled order.
    muts = files[len(originals):]
    rng.shuffle(muts)
    files = originals + muts
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", DRIVER, json.dumps(files), str(SECONDS), str(out_dir)],
                       capture_output=True, text=True, timeout=SECONDS + 240, env=env)
    assert r.returncode == 0, f"the driver died (exit {r.returncode}): {r.stderr[-3000:]}"
    doc = json.loads(r.stdout.strip().splitlines()[-1])
    results = doc["results"]
    assert len(results) >= 2 * (len(originals) + 40), f"only {len(results)} runs in {SECONDS} s"
    report = os.environ.get("CLPOST_MATRIX_REPORT")
    bad = []
    for res in results:
        lines = [ln for ln in res["err"].splitlines() if ln.strip()]
        original = res["mutation"].startswith("none")
        # A truncated file is always refused: it never reads as a frame with passes missing.
        want = (0,) if original else (2,) if res["mutation"].startswith("truncated") else (0, 2)
        ok = res["code"] in want and "Traceback" not in res["err"] and not res["chatter"] \
            and (res["code"] == 0 or (len(lines) <= 3 and not res["output"]))
        if not ok:
            bad.append(res)
    if report:
        import collections

        by = collections.defaultdict(list)
        for res in results:
            by[(res["mutation"].split(" (")[0], res["cmd"])].append(res)
        with open(report, "a") as f:
            for (mut, cmd), rs in sorted(by.items()):
                codes = sorted({r_["code"] for r_ in rs})
                nlines = max(len([ln for ln in r_["err"].splitlines() if ln.strip()]) for r_ in rs)
                f.write(json.dumps({"case": f"fuzz: {mut} ×{len(rs)}", "command": f"clpost {cmd} <mutated EXR>",
                                    "exit": "/".join(map(str, codes)), "lines": nlines,
                                    "verdict": "FAILED" if any(r_ in bad for r_ in rs) else "held",
                                    "message": next((r_["err"].strip().splitlines()[-1] for r_ in rs
                                                     if r_["err"].strip()), "").replace(str(tmp_path) + "/", "")})
                        + "\n")
    assert not bad, json.dumps(bad[:5], indent=1)
    # Every mutation kind was tried, and most damaged files were refused (not silently read).
    kinds = {res["mutation"].split(" (")[0] for res in results}
    assert len(kinds) >= 8, kinds
    refused = sum(res["code"] == 2 for res in results if not res["mutation"].startswith("none"))
    assert refused > len(results) // 3
