"""Regenerate the stage-order table in clpost/stages/__init__.py's docstring from
:data:`clpost.stages.PHYSICAL_ORDER` (and each stage's ``order``).

    PYTHONPATH=. python tools/gen_stage_table.py          # rewrite the table
    PYTHONPATH=. python tools/gen_stage_table.py --check  # exit 1 if it is stale
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from clpost import stages

BEGIN, END = ".. stage-order-table: begin\n", ".. stage-order-table: end\n"


def regenerate(text: str) -> str:
    """``text`` (the module's source) with the lines between the markers replaced by the table."""
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return head + BEGIN + "\n" + stages.order_table() + "\n\n" + END + tail


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only check; exit 1 if the table is stale")
    args = ap.parse_args(argv)
    path = Path(stages.__file__)
    old = path.read_text()
    new = regenerate(old)
    if args.check:
        if new != old:
            print(f"{path}: the stage-order table is stale; run python tools/gen_stage_table.py", file=sys.stderr)
            return 1
        return 0
    if new != old:
        path.write_text(new)
        print(f"rewrote the table in {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
