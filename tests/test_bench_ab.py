"""clpost bench --against: a git revision and this tree in one process."""
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _git_ok() -> bool:
    try:
        return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True).returncode == 0
    except OSError:
        return False


@pytest.mark.skipif(not _git_ok(), reason="needs a clpost git checkout (git archive of HEAD)")
def test_head_against_itself_runs_both_and_agrees(monkeypatch):
    from clpost.bench_ab import compare, format_rows

    monkeypatch.chdir(ROOT)
    rows = compare("HEAD", ["worst"], [(48, 32)], ["draft"], repeats=1, warmup=1)
    kernels = {r["kernel"] for r in rows}
    assert {"dof", "distortion", "(all kernels)"} <= kernels
    assert all(r["old_ms"] > 0 and r["new_ms"] > 0 and r["ratio"] > 0 for r in rows)
    # the same code on the same frame gives the same pixels
    assert all(r["max_abs_diff"] == 0 for r in rows)
    assert "| worst | 48x32 | draft | dof |" in format_rows(rows, "HEAD")


def test_an_unknown_revision_is_one_line():
    from clpost.bench_ab import load_revision
    from clpost.errors import InputError

    with pytest.raises(InputError, match="--against no-such-rev-xyz: git archive failed"):
        load_revision("no-such-rev-xyz", ROOT)
