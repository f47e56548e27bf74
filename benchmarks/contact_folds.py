"""Shared files folded with and without self-contact (issue 42): crossings, pairs, times.

    python benchmarks/contact_folds.py              # the files listed in FILES
    python benchmarks/contact_folds.py --max-time 300

For each file of ``../shared/patterns`` in :data:`FILES` (the bases, those whose fold at the
defaults ends with faces crossing, and two models whose layers close on each other mid-path,
airplane.svg and flappingBird.svg), Newton at the defaults (float64) folds it twice:
``contact=False`` and ``contact=True``. Each row gives the status, iterations, compile and run
time, the mean fold-angle error (degrees), creases through pi, crossing face pairs
(``result.intersections``), and with contact the pairs within ``dhat`` and the least distance
over ``dhat``. Each file is folded in a fresh process. Times are wall times on this machine;
compare within one run. Writes
``contact_folds.csv`` and ``contact_folds.md`` in ``benchmarks/results``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

os.environ.setdefault("JAX_ENABLE_X64", "1")

import jax  # noqa: E402
from cores import cpu_name, usable_cores  # noqa: E402 (benchmarks/, the script's folder)

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import origami_jax  # noqa: E402
from origami_jax import fold, io  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "patterns"
RESULTS = ROOT / "benchmarks" / "results"
FILES = (
    "origami-simulator/Bases/squareBase.svg",
    "origami-simulator/Bases/waterbombBase.svg",
    "origami-simulator/Bases/birdBase.svg",
    "origami-simulator/Bases/frogBase.svg",
    "origami-simulator/Origami/airplane.svg",
    "origami-simulator/Origami/flappingBird.svg",
    "origami-simulator/Curved/curvedcrease2.svg",
    "origami-simulator/doc/cuts.svg",
    "origami-simulator/doc/opacityExamples.svg",
    "origami-simulator/doc/triangulations.svg",
    "origami-simulator/doc/hinges.svg",
)


def measure(name: str, contact: bool, max_time: float) -> dict:
    cp = io.load(SHARED / name)
    r = fold(cp, contact=contact, max_time=max_time)
    return {
        "file": name,
        "contact": contact,
        "mesh_vertices": cp.mesh.num_vertices,
        "status": r.status.name.lower(),
        "iterations": r.iterations,
        "compile_time_s": round(r.compile_time, 3),
        "wall_time_s": round(r.wall_time, 4),
        "fold_angle_error_mean_deg": float(np.degrees(r.fold_angle_error_mean)),
        "through_pi": len(r.through_pi),
        "intersections": len(r.intersections),
        "contact_pairs": r.contact_pairs if contact else "",
        "min_distance_over_dhat": f"{r.contact_min_ratio:.4g}" if contact else "",
    }


def write(rows: list[dict], max_time: float) -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)
    with open(RESULTS / "contact_folds.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    head = (
        f"Measured on {platform.machine()}, {usable_cores()} cores, {cpu_name()}, jax "
        f"{jax.__version__}, origami_jax {origami_jax.__version__}; float64, Newton, the "
        "defaults (`contact=True`: dhat 1e-3 of the diameter or half the flat clearance), "
        f"at most {max_time:g} s per fold (`--max-time`). Times: this machine's wall clock; "
        "compare within the run.\n\n"
    )
    cols = list(rows[0])
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for row in rows:
        cells = [f"{v:.3g}" if isinstance(v, float) else str(v) for v in row.values()]
        lines.append("| " + " | ".join(cells) + " |")
    (RESULTS / "contact_folds.md").write_text(head + "\n".join(lines) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-time", type=float, default=180.0, help="per fold, seconds")
    parser.add_argument("--one", help=argparse.SUPPRESS)  # a child: one file, rows as JSON
    args = parser.parse_args()
    if not SHARED.is_dir():
        raise SystemExit(f"{SHARED} is not present")
    if args.one:
        origami_jax.tune_process()
        for contact in (False, True):
            print(json.dumps(measure(args.one, contact, args.max_time)), flush=True)
        return
    rows = []
    for name in FILES:
        # each file in a fresh process: one process's compiled contact programs add up (on a
        # long list, past what LLVM's code memory holds)
        argv = [sys.executable, __file__, "--one", name, "--max-time", str(args.max_time)]
        proc = subprocess.run(argv, capture_output=True, text=True)
        done = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
        if proc.returncode != 0:  # a crash is a result too: the row says so
            last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
            done.append({**dict.fromkeys(done[0] if done else rows[0]), "file": name})
            done[-1].update(contact=len(done) > 1, status=f"crashed: {last}")
        for row in done:
            rows.append(row)
            print(row, flush=True)
    write(rows, args.max_time)


if __name__ == "__main__":
    main()
