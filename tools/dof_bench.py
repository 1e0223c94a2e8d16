"""Measure the dof trade: ms/frame and error against the accumulation-buffer reference per quality.

    PYTHONPATH=. python tools/dof_bench.py [--samples 128,64] [--repeats 5] [--out docs]

Writes docs/benchmarks.md (table + command) and docs/dof_error_vs_time.png. Same as
`clpost bench --dof`.
"""
import argparse
import sys
from pathlib import Path

from clpost.dof_bench import format_dof_table, plot, run_dof_bench
from clpost.runtime import get_runtime


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--samples", default="128,64", help="reference aperture samples per size (640x360, 1280x720)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--out", default="docs")
    p.add_argument("--save", default=None, help="folder for the reference and output images (PNG + arrays)")
    a = p.parse_args(argv)
    samples = tuple(int(s) for s in a.samples.split(","))
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, conv = run_dof_bench(samples=samples, repeats=a.repeats, save_dir=a.save)
    table = format_dof_table(rows, conv, get_runtime().name)
    cmd = "PYTHONPATH=. python tools/dof_bench.py " + " ".join(sys.argv[1:] if argv is None else argv)
    # the Blender Defocus section belongs to tools/compare_blender_dof.py: keep it across reruns
    old = (out / "benchmarks.md").read_text() if (out / "benchmarks.md").exists() else ""
    keep = old[old.find("\n## dof: Blender"):] if "\n## dof: Blender" in old else ""
    (out / "benchmarks.md").write_text(
        "# Benchmarks\n\n## dof: speed vs accuracy (demo scene, 50 mm f/2 focused at 3 m, 6 blades)\n\n"
        f"Command: `{cmd.strip()}`\n\n" + table + "\n\n![error vs time](dof_error_vs_time.png)\n" + keep)
    plot(rows, out / "dof_error_vs_time.png")
    print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
