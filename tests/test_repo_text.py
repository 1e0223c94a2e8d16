"""The repository's text files as a user reads them: no merge leftovers, no dead relative links.

A merge once left `<<<<<<<`/`>>>>>>>` markers in docs/benchmarks.md for a whole release; these
checks read every tracked text file, so the next one fails CI instead.
"""
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TEXT = (".py", ".md", ".cl", ".h", ".toml", ".cfg", ".txt", ".json", ".yaml", ".yml", ".sh")


def _tracked():
    try:
        out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    return [ROOT / p for p in out.stdout.splitlines() if p.endswith(TEXT) and (ROOT / p).is_file()]


_MARKER = re.compile(r"^(<{7} |>{7} |={7}$)", re.M)


def test_no_merge_conflict_markers():
    bad = []
    for p in _tracked():
        text = p.read_text(encoding="utf-8", errors="replace")
        for m in _MARKER.finditer(text):
            bad.append(f"{p.relative_to(ROOT)}:{text.count(chr(10), 0, m.start()) + 1}")
    assert not bad, "merge-conflict markers: " + ", ".join(bad)


_LINK = re.compile(r"\]\(([^)\s#]+)(?:#[^)]*)?\)")


def test_relative_links_in_markdown_resolve():
    bad = []
    for p in _tracked():
        if p.suffix != ".md":
            continue
        for target in _LINK.findall(p.read_text(encoding="utf-8")):
            if re.match(r"^[a-z]+:", target):  # http:, https:, mailto:
                continue
            if not (p.parent / target).exists():
                bad.append(f"{p.relative_to(ROOT)} -> {target}")
    assert not bad, "dead relative links: " + ", ".join(bad)
