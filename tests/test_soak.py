"""Kill/resume soak, short CI version of ``tools/soak.py`` (the full run has ≥ 50 cycles; its
result is in docs/reliability.md): SIGKILL/SIGTERM at random points, serial and ``--workers 2``,
ending with every frame bit-identical to an uninterrupted run and no stray file."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_kill_resume_soak_short():
    r = subprocess.run([sys.executable, str(ROOT / "tools" / "soak.py"), "--cycles", "3", "--workers-every", "3",
                        "--frames", "4", "--size", "160x90", "--seed", "3"],
                       capture_output=True, text=True, timeout=400, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    summary = json.loads(r.stdout.strip().splitlines()[-1])
    assert r.returncode == 0, r.stdout + r.stderr
    assert summary["failures"] == [] and summary["final_bit_identical"] and summary["stray_files"] == []
    assert summary["serial"] == 2 and summary["workers"] == 1
