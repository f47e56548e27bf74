"""Stiff and extreme cases on the shared files that have a zero-energy folded state.

    python benchmarks/extreme.py            # or: python benchmarks/run.py --part extreme
    python benchmarks/extreme.py --quick    # the first such file only

The real-patterns issue asks that a pattern with a zero-energy folded state reach it (fold-angle
error at most 1e-6 rad, no crease past pi) at every axial : crease stiffness ratio from 1e2 to
1e8 and at sheet sizes from 1e-6 to 1e6; the tests check generated patterns
(``tests/test_path.py``), and this adds the files of ``../shared/patterns`` that have such a
state. A file has one where its fold at the defaults reaches its targets (fold-angle error at
most 1e-6 rad) with every bar at its rest length (strain at most :data:`UNSTRAINED`): that fold
is the proof. A file whose fold at the defaults reaches its targets only by straining its bars
(drawn a little off flat-foldability, say) has no such state: its targets are an equilibrium
of a prestressed sheet, which at a high enough ratio buckles (the state's Hessian turns
indefinite) or is not the lowest one. Those files are folded too and reported apart, with each
fold's energy against the energy of the targets (the fold at the defaults, under the case's
parameters): an end state below it is an equilibrium the targets cannot beat.

Each file is folded at the defaults with
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

import jax.numpy as jnp  # noqa: E402

from origami_jax import CreasePattern, PatternError, fold, io  # noqa: E402
from origami_jax.energy import energy, make_params, make_structure  # noqa: E402
from origami_jax.tuning import tune_process  # noqa: E402

TUNED = tune_process()
SHARED = Path(__file__).resolve().parents[2] / "shared" / "patterns"
RATIOS = (1e2, 1e4, 1e6, 1e8)
SCALES = (1e-6, 1e6)
REACHED = 1e-6  # rad: the fold-angle error of a state that reaches the targets
# the largest bar strain of a zero-energy state: far above a converged fold's rounding, far
# below the strain a pattern drawn a little off its folded geometry needs to reach its targets
UNSTRAINED = 1e-9


def scaled(cp: CreasePattern, scale: float) -> CreasePattern:
    return CreasePattern(
        cp.vertices * scale, cp.edges, cp.faces, cp.assignments, cp.fold_angles, cp.name
    )


def target_energy(cp: CreasePattern, positions, stiffness: dict | None) -> float:
    """The energy of ``positions`` (a state at the targets) under a case's stiffness."""
    params = make_params(cp, 1.0, stiffness, jnp.float64)
    structure = make_structure(cp.mesh)
    return float(energy(jnp.asarray(positions), structure, params))


def row(name: str, case: str, result, target_strain: float, at_target: float) -> dict:
    return {
        "file": name,
        "zero_energy_state": target_strain <= UNSTRAINED,
        "target_strain": target_strain,
        "case": case,
        "status": result.status.name.lower(),
        "path": result.path,
        "iterations": result.iterations,
        "compile_time_s": result.compile_time,
        "wall_time_s": result.wall_time,
        "fold_angle_error_max_rad": result.fold_angle_error_max,
        "through_pi": len(result.through_pi),
        "collapsed": len(result.collapsed),
        "energy": result.energy,
        "target_energy": at_target,
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
        strain = base.strain_max
        rows.append(row(name, "defaults", base, strain, base.energy))
        for ratio in RATIOS:
            stiffness = {"axial": 1.0, "facet": 20.0 / ratio, "crease": 1.0 / ratio}
            result = fold(cp, stiffness=stiffness, max_time=max_time)
            at_target = target_energy(cp, base.positions, stiffness)
            rows.append(row(name, f"ratio {ratio:.0e}", result, strain, at_target))
        for scale in SCALES:
            big = scaled(cp, scale)
            at_target = target_energy(big, base.positions * scale, None)
            result = fold(big, max_time=max_time)
            rows.append(row(name, f"scale {scale:.0e}", result, strain, at_target))
        for r in rows[-1 - len(RATIOS) - len(SCALES) :]:
            print(
                f"{r['file']:50s} {r['case']:12s} {r['status']:10s} {r['iterations']:6d} it "
                f"{r['wall_time_s']:8.3f} s  err {r['fold_angle_error_max_rad']:.1e} rad  "
                f"energy {r['energy']:.3e} (targets {r['target_energy']:.3e})",
                flush=True,
            )
        if quick:
            break
    return rows


def lower(r: dict) -> bool:
    """Whether a fold ended converged below the energy of the targets (by more than rounding)."""
    return r["status"] == "converged" and r["energy"] < r["target_energy"] * (1 - 1e-9)


def table(rows: list[dict]) -> list[str]:
    lines = [
        "| file | target strain | case | status | path | iterations | compile (s) | fold (s) | "
        "max fold-angle error (rad) | through pi | collapsed | energy | targets' energy | "
        "reached |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['file']} | {r['target_strain']:.1e} | {r['case']} | {r['status']} | "
            f"{r['path']} | {r['iterations']} | {r['compile_time_s']:.2f} | "
            f"{r['wall_time_s']:.3g} | {r['fold_angle_error_max_rad']:.2e} | {r['through_pi']} | "
            f"{r['collapsed']} | {r['energy']:.3e} | {r['target_energy']:.3e} | "
            f"{'yes' if r['reached'] else 'no'} |"
        )
    return lines


def markdown(rows: list[dict], machine: str) -> str:
    zero = [r for r in rows if r["zero_energy_state"]]
    strained = [r for r in rows if not r["zero_energy_state"]]
    cases = [r for r in zero if r["case"] != "defaults"]
    others = [r for r in strained if r["case"] != "defaults"]
    missed = [r for r in others if not r["reached"]]
    strains = [r["target_strain"] for r in strained if r["case"] == "defaults"]
    lines = [
        f"Measured on {machine}; float64, Newton, the defaults but for the case's stiffness "
        f"(axial 1, facet 20 / ratio, crease 1 / ratio) or sheet size. Files: those of "
        f"../shared/patterns whose fold at the defaults reaches its targets (fold-angle error "
        f"<= {REACHED:g} rad); a file has a zero-energy folded state where that fold's bars are "
        f"at their rest lengths ('target strain', its largest strain, <= {UNSTRAINED:g}). "
        f"'reached': converged, error <= {REACHED:g} rad, no crease through pi, no collapsed "
        f"triangle. 'targets' energy': the energy of the fold at the defaults (the targets' "
        f"state) under the case's parameters.",
        "",
        f"{len({r['file'] for r in zero})} files with a zero-energy folded state, {len(cases)} "
        f"stiff or scaled folds: {sum(r['reached'] for r in cases)} reached it.",
        "",
    ]
    if strained:
        lines += [
            f"{len({r['file'] for r in strained})} files reach their targets at the defaults only "
            f"by straining bars (target strain {min(strains):.1e} to {max(strains):.1e}): no "
            f"zero-energy state. Of their {len(others)} stiff or scaled folds, "
            f"{len(others) - len(missed)} end at the targets; of the other {len(missed)}, "
            f"{sum(lower(r) for r in missed)} converge to a state of lower energy than the "
            f"targets' (once the bars are stiff enough against the creases, the strained fold "
            f"buckles or is no longer the lowest state) and "
            f"{sum(r['status'] != 'converged' for r in missed)} end unconverged.",
            "",
        ]
    lines += ["## Files with a zero-energy folded state", ""] + table(zero)
    if strained:
        lines += ["", "## Files whose targets strain the bars", ""] + table(strained)
    return "\n".join(lines) + "\n"


def plot(rows: list[dict], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = [c for c in dict.fromkeys(r["case"] for r in rows)]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for case in cases:
        pick = [r for r in rows if r["case"] == case and r["zero_energy_state"]]
        ax.scatter(
            [r["wall_time_s"] for r in pick],
            [max(r["fold_angle_error_max_rad"], 1e-17) for r in pick],
            label=case,
            s=18,
        )
    strained = [r for r in rows if not r["zero_energy_state"]]
    if strained:
        ax.scatter(
            [r["wall_time_s"] for r in strained],
            [max(r["fold_angle_error_max_rad"], 1e-17) for r in strained],
            label="targets strain the bars (any case)",
            marker="x",
            color="grey",
            s=18,
        )
    ax.axhline(REACHED, color="grey", lw=0.8, ls="--")
    ax.set(xscale="log", yscale="log", xlabel="fold time (s, compile apart)")
    ax.set_ylabel("max fold-angle error (rad)")
    ax.set_title("Shared files reaching their targets: stiff and scaled")
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
