"""Error against run time: fold benchmark scenes with each solver, write CSV, PNG and markdown.

    python benchmarks/run.py            # all cases, results in benchmarks/results/
    python benchmarks/run.py --quick    # small cases only (a smoke run)

Every case is folded twice: the first run's compile time is reported, the second run's wall time
(compile excluded). Times are for the machine the script runs on; compare solvers and cases by
ratios measured in the same run. Plots need matplotlib (``pip install ".[bench]"``); without it
the CSV and markdown are still written.
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("JAX_ENABLE_X64", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from origami_jax import fold, patterns  # noqa: E402
from origami_jax.kinematics import rigid_fold  # noqa: E402
from origami_jax.solvers import SOLVERS  # noqa: E402

THRESHOLDS = (1e-3, 1e-6, 1e-8)


def cases(quick: bool):
    """(name, pattern, fold keyword arguments, exact reference shape or None)."""
    seed = patterns.seed_waterbomb()
    yield "seed_waterbomb", seed, {"stiffness": patterns.SEED_WATERBOMB_STIFFNESS}, None
    sizes = (10,) if quick else (10, 30)
    for n in sizes:
        cp = patterns.miura_ori(n, n)
        yield f"miura_{n}x{n}", cp, {}, rigid_fold(cp)
    if not quick:
        cp = patterns.kresling(n=6, stories=2)
        yield "kresling_6x2", cp, {}, rigid_fold(cp)
        cp = patterns.yoshimura(6, 4)
        yield "yoshimura_6x4", cp, {}, rigid_fold(cp)


def time_to(history: dict, key: str, threshold: float) -> float:
    """Wall time of the first sample at or below ``threshold`` (NaN if never)."""
    hit = np.flatnonzero(history[key] <= threshold)
    return float(history["wall_time"][hit[0]]) if len(hit) else float("nan")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small cases only")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    parser.add_argument("--solvers", default=",".join(SOLVERS), help="comma-separated names")
    parser.add_argument("--tol", type=float, default=1e-10, help="grad_norm_rel tolerance")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    device = jax.devices()[0]
    machine = (
        f"{platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}, "
        f"device {device.platform}: {device.device_kind}"
    )
    summary, history_rows, plots = [], [], {}
    for name, cp, kwargs, reference in cases(args.quick):
        for solver in args.solvers.split(","):
            first = fold(cp, solver=solver, tol=args.tol, reference_positions=reference, **kwargs)
            r = fold(cp, solver=solver, tol=args.tol, reference_positions=reference, **kwargs)
            row = {
                "case": name,
                "solver": solver,
                "vertices": cp.mesh.num_vertices,
                "converged": r.converged,
                "iterations": r.iterations,
                "compile_time_s": first.compile_time,
                "wall_time_s": r.wall_time,
                "fold_angle_error_max": r.fold_angle_error_max,
                "strain_max": r.strain_max,
                "energy": r.energy,
                "grad_norm_rel": r.grad_norm_rel,
                "shape_error": r.shape_error if r.shape_error is not None else float("nan"),
            }
            key = "grad_norm_rel" if reference is None else "fold_angle_error_max"
            for t in THRESHOLDS:
                row[f"time_to_{t:g}_s"] = time_to(r.history, key, t)
            row["threshold_on"] = key
            summary.append(row)
            for k in range(len(r.history["wall_time"])):
                history_rows.append(
                    {
                        "case": name,
                        "solver": solver,
                        **{f: float(r.history[f][k]) for f in r.history},
                    }
                )
            plots.setdefault(name, []).append((solver, r.history))
            print(
                f"{name:16s} {solver:8s} {r.iterations:6d} it  "
                f"compile {first.compile_time:6.2f} s  run {r.wall_time:8.4f} s  "
                f"err {r.fold_angle_error_max:.2e}  "
                f"{'converged' if r.converged else r.reason}",
                flush=True,
            )

    write_csv(out / "summary.csv", summary)
    write_csv(out / "history.csv", history_rows)
    table = markdown(summary, machine)
    (out / "results.md").write_text(table)
    print(table)
    try:
        plot(plots, out)
    except ImportError:
        print("matplotlib not installed: no plots (pip install '.[bench]')", file=sys.stderr)
    return 0


def write_csv(path: Path, rows: list[dict]) -> None:
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def markdown(rows: list[dict], machine: str) -> str:
    def fmt(v):
        return "-" if v != v else f"{v:.3g}"

    head = ["case", "solver", "vertices", "iterations", "compile (s)", "run (s)"]
    head += [f"to {t:g} (s)" for t in THRESHOLDS]
    head += ["final fold-angle error (rad)", "strain_max", "grad_norm_rel", "shape_error"]
    lines = [
        f"Measured {time.strftime('%Y-%m-%d')} on {machine}; float64. Columns 'to 1e-3' etc.:"
        " wall time until fold_angle_error_max (rad) first fell to that value, or, for the"
        " seed's scene (not rigid-foldable), grad_norm_rel.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for r in rows:
        cells = [
            r["case"],
            r["solver"],
            str(r["vertices"]),
            f"{r['iterations']}{'' if r['converged'] else ' (not converged)'}",
            f"{r['compile_time_s']:.2f}",
            f"{r['wall_time_s']:.4f}",
        ]
        cells += [fmt(r[f"time_to_{t:g}_s"]) for t in THRESHOLDS]
        cells += [
            fmt(r["fold_angle_error_max"]),
            fmt(r["strain_max"]),
            fmt(r["grad_norm_rel"]),
            fmt(r["shape_error"]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot(plots: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for name, runs in plots.items():
        fig, ax = plt.subplots(figsize=(5.5, 4))
        for solver, h in runs:
            t = np.maximum(h["wall_time"], 1e-5)
            ax.loglog(t, h["fold_angle_error_max"], label=f"{solver}: fold_angle_error_max (rad)")
            ax.loglog(t, h["grad_norm_rel"], "--", label=f"{solver}: grad_norm_rel")
            ax.loglog(t, np.maximum(h["strain_max"], 1e-17), ":", label=f"{solver}: strain_max")
        ax.set_xlabel("wall time after compilation (s)")
        ax.set_ylabel("error")
        ax.set_title(f"{name}: error against run time")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out / f"{name}.png", dpi=110)
        plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
