"""Peak memory and the time limit of long folds: one fold per process, so each peak is its own.

    python benchmarks/memory.py                           # hinges.svg, SuperLU, max_time 5 and 20
    python benchmarks/memory.py --backend pardiso --max-time 5 20 40
    python benchmarks/memory.py --file Curved/wavy_pleats.svg --max-time 30

Folds a file of ``../shared/patterns/origami-simulator`` at the defaults (Newton; sparse above
200 vertices) with the given host backend, once per ``max_time``, each in a fresh process, and
prints its iterations, its solve time (``result.wall_time``: compile time excluded, as
``max_time`` counts it), how far that ran past ``max_time``, and the process's peak resident
memory (``ru_maxrss``). A leak shows as a peak that grows with the iterations. Nothing is
written to ``benchmarks/results``: times and peaks on this shared machine are for comparing
within one run.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "patterns" / "origami-simulator"

_ONE = """
import resource, sys
import origami_jax as oj
from origami_jax.solvers import hostsparse
path, backend, max_time = sys.argv[1], sys.argv[2], float(sys.argv[3])
with hostsparse.using(backend):
    r = oj.fold(oj.load(path), max_time=max_time)
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # KiB on Linux
print(f"{r.iterations} {r.wall_time:.2f} {r.compile_time:.1f} {peak:.2f}")
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--file", default="doc/hinges.svg")
    parser.add_argument("--backend", default="superlu", choices=("pardiso", "cholmod", "superlu"))
    parser.add_argument("--max-time", type=float, nargs="+", default=[5.0, 20.0])
    args = parser.parse_args()
    path = SHARED / args.file
    print(f"{args.file}, {args.backend}")
    print("max_time s | iterations | solve s | past max_time s | compile s | peak RSS GiB")
    for max_time in args.max_time:
        out = subprocess.run(
            [sys.executable, "-c", _ONE, str(path), args.backend, str(max_time)],
            capture_output=True,
            text=True,
            check=True,
            cwd=ROOT,
        )
        iterations, solve, compile_s, peak = out.stdout.split()[-4:]
        past = float(solve) - max_time
        print(f"{max_time:g} | {iterations} | {solve} | {past:+.2f} | {compile_s} | {peak}")


if __name__ == "__main__":
    main()
