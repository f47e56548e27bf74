"""Stiff and extreme cases on the shared files that have a zero-energy folded state.

    python benchmarks/extreme.py            # or: python benchmarks/run.py --part extreme
    python benchmarks/extreme.py --quick    # the first such file only

The real-patterns issue asks that a pattern with a zero-energy folded state reach it (fold-angle
error at most 1e-6 rad, no crease past pi) at every axial : crease stiffness ratio from 1e2 to
1e8 and at sheet sizes from 1e-6 to 1e6; the tests check generated patterns
(``tests/test_path.py``), and this adds the files of ``../shared/patterns`` that have such a
state. A file has one where its fold at the defaults reaches its targets (fold-angle error at
most 1e-6 rad): that fold is the proof. Each such file is then folded at the defaults with
``stiffness={"axial": 1, "facet": 20 / ratio, "crease": 1 / ratio}`` for each ratio, and with
its vertices scaled by 1e-6 and by 1e6 (each solve capped at ``--max-time``, 120 s). Writes
``extreme_summary.csv``, ``extreme_results.md`` and (with matplotlib) ``extreme_errors.png``
in ``benchmarks/results``.
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import sys
from pathlib import Path

os.environ.setdefault("JAX_ENABLE_X64", "1")

import jax  # noqa: E402
from cores import cpu_name, usable_cores  # noqa: E402 (benchmarks/, the script's folder)

jax.config.update("jax_enable_x64", True)

from origami_jax import CreasePattern, PatternError, fold, io  # noqa: E402
from origami_jax.tuning import tune_process  # noqa: E402

TUNED = tune_process()
SHARED = Path(__file__).resolve().parents[2] / "shared" / "patterns"
RATIOS = (1e2, 1e4, 1e6, 1e8)
SCALES = (1e-6, 1e6)
REACHED = 1e-6  # rad: the fold-angle error of a state that reaches the targets


def scaled(cp: CreasePattern, scale: float) -> CreasePattern:
    return CreasePattern(
        cp.vertices * scale, cp.edges, cp.faces, cp.assignments, cp.fold_angles, cp.name
    )


def row(name: str, case: str, result) -> dict:
    return {
        "file": name,
        "case": case,
        "status": result.status.name.lower(),
        "path": result.path,
        "iterations": result.iterations,
        "compile_time_s": result.compile_time,
        "wall_time_s": result.wall_time,
        "fold_angle_error_max_rad": result.fold_angle_error_max,
        "through_pi": len(result.through_pi),
        "collapsed": len(result.collapsed),
        "reached": bool(
            result.converged
            and result.fold_angle_error_max <= REACHED
            and not len(result.through_pi)
            and not len(result.collapsed)
        ),
    }


def run(quick: bool, max_time: float) -> list[dict]:
    rows = []
    if not SHARED.is_dir():
        print(f"{SHARED} is absent: nothing to fold", file=sys.stderr)
        return rows
    for path in sorted(SHARED.rglob("*")):
        if path.suffix.lower() not in (".svg", ".fold"):
            continue
        name = str(path.relative_to(SHARED))
        try:
            cp = io.load(path)
        except PatternError as err:
            print(f"{name}: does not load: {err}", file=sys.stderr)
            continue
        base = fold(cp, max_time=max_time)
        if not (base.converged and base.fold_angle_error_max <= REACHED):
            continue  # no zero-energy state shown: the targets are not all reachable
        rows.append(row(name, "defaults", base))
        for ratio in RATIOS:
            stiffness = {"axial": 1.0, "facet": 20.0 / ratio, "crease": 1.0 / ratio}
            result = fold(cp, stiffness=stiffness, max_time=max_time)
            rows.append(row(name, f"ratio {ratio:.0e}", result))
        for scale in SCALES:
            rows.append(row(name, f"scale {scale:.0e}", fold(scaled(cp, scale), max_time=max_time)))
        for r in rows[-1 - len(RATIOS) - len(SCALES) :]:
            print(
                f"{r['file']:50s} {r['case']:12s} {r['status']:10s} {r['iterations']:6d} it "
                f"{r['wall_time_s']:8.3f} s  err {r['fold_angle_error_max_rad']:.1e} rad",
                flush=True,
            )
        if quick:
            break
    return rows


def markdown(rows: list[dict], machine: str) -> str:
    files = sorted({r["file"] for r in rows})
    cases = [r for r in rows if r["case"] != "defaults"]
    reached = sum(r["reached"] for r in cases)
    lines = [
        f"Measured on {machine}; float64, Newton, the defaults but for the case's stiffness "
        f"(axial 1, facet 20 / ratio, crease 1 / ratio) or sheet size. Files: those of "
        f"../shared/patterns whose fold at the defaults reaches its targets (fold-angle error "
        f"<= {REACHED:g} rad). 'reached': converged, error <= {REACHED:g} rad, no crease "
        f"through pi, no collapsed triangle.",
        "",
        f"{len(files)} files, {len(cases)} stiff or scaled folds: {reached} reached the "
        f"zero-energy state.",
        "",
        "| file | case | status | path | iterations | compile (s) | fold (s) | "
        "max fold-angle error (rad) | through pi | collapsed | reached |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['file']} | {r['case']} | {r['status']} | {r['path']} | {r['iterations']} | "
            f"{r['compile_time_s']:.2f} | {r['wall_time_s']:.3g} | "
            f"{r['fold_angle_error_max_rad']:.2e} | {r['through_pi']} | {r['collapsed']} | "
            f"{'yes' if r['reached'] else 'no'} |"
        )
    return "\n".join(lines) + "\n"


def plot(rows: list[dict], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = [c for c in dict.fromkeys(r["case"] for r in rows)]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for case in cases:
        pick = [r for r in rows if r["case"] == case]
        ax.scatter(
            [r["wall_time_s"] for r in pick],
            [max(r["fold_angle_error_max_rad"], 1e-17) for r in pick],
            label=case,
            s=18,
        )
    ax.axhline(REACHED, color="grey", lw=0.8, ls="--")
    ax.set(xscale="log", yscale="log", xlabel="fold time (s, compile apart)")
    ax.set_ylabel("max fold-angle error (rad)")
    ax.set_title("Shared files with a zero-energy state: stiff and scaled")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "extreme_errors.png", dpi=120)
    plt.close(fig)


def main(out: Path, quick: bool = False, max_time: float = 120.0) -> None:
    out.mkdir(parents=True, exist_ok=True)
    machine = (
        f"{platform.machine()}, {usable_cores()} cores, jax {jax.__version__}, "
        f"CPU {cpu_name()}, process tuning (origami_jax.tuning): {TUNED}"
    )
    rows = run(quick, max_time)
    if not rows:
        return
    with open(out / "extreme_summary.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    table = markdown(rows, machine)
    (out / "extreme_results.md").write_text(table)
    print(table)
    try:
        plot(rows, out)
    except ImportError:
        print("matplotlib not installed: no plot (pip install '.[bench]')")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the first such file only")
    parser.add_argument("--max-time", type=float, default=120.0, help="seconds per solve")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args()
    main(Path(args.out), quick=args.quick, max_time=args.max_time)
