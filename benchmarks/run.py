"""Error against run time: fold benchmark scenes with each solver, write CSV, PNG and markdown.

    python benchmarks/run.py            # all cases, results in benchmarks/results/
    python benchmarks/run.py --quick    # small cases only (a smoke run)
    python benchmarks/run.py --part stiffness   # only the stiffness sweep
    python benchmarks/run.py --part files       # every file under ../shared/patterns
    python benchmarks/run.py --part svg         # every solver on the shared SVG files
    python benchmarks/run.py --part batch       # fold_batch against a loop (benchmarks/batch.py)
    python benchmarks/run.py --part linear      # Newton's systems: direct vs PCG (linear.py)
    python benchmarks/run.py --part extreme     # stiff and scaled shared files (extreme.py)

Cases: the seed's scene, Miura-ori 10 x 10, 30 x 30 and 100 x 100, a Yoshimura, a Kresling, and
every FOLD file under ../shared/patterns that loads (skipped when that folder is absent); the
solvers Newton, L-BFGS and FIRE dynamics, plus Origami Simulator's scheme (semi-implicit Euler,
bar damping, its time step) on the Miura-ori up to 30 x 30 for comparison. A second part
sweeps the axial : crease stiffness ratio from 1 to 1e8 on a 10 x 10 Miura-ori (files
``stiffness_*``). A third loads every SVG and FOLD file under ../shared/patterns and folds it
with the defaults (Newton; files ``files_*``); a fourth folds every SVG file there with each
solver, as the main part does the FOLD files (files ``svg_*``). Each solve is capped at
``--max-time`` seconds (120; 30 in the sweep and the SVG part).

Compile time comes from a first call that compiles and runs no iteration; the wall time and
the (wall time, error) series from a second call, compile excluded; a solve under a second is
timed as the median of 7 calls. Newton's series is taken from a third call that records every
iteration (a host round trip each, about 0.5 ms); its wall time is the second call's, and for a
solve under a second its "to 1e-x" times are those of plain solves stopped after the iteration
that first reached 1e-x (median of 7), so no round trip is counted. Times are for the machine
the script runs on; compare solvers and cases by the ratios measured in the same run. Plots
need matplotlib (``pip install ".[bench]"``); without it the CSV and markdown are still written.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import functools
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("JAX_ENABLE_X64", "1")

import jax  # noqa: E402
from cores import cpu_devices, cpu_name, usable_cores  # noqa: E402 (benchmarks/)

jax.config.update("jax_enable_x64", True)
# two JAX devices per core, as benchmarks/batch.py (fold() uses the first; fold_batch all)
jax.config.update("jax_num_cpu_devices", cpu_devices())

import numpy as np  # noqa: E402

from origami_jax import PatternError, fold, io, patterns  # noqa: E402
from origami_jax.kinematics import rigid_fold  # noqa: E402
from origami_jax.solvers import hostsparse, origami_simulator  # noqa: E402
from origami_jax.tuning import tune_process  # noqa: E402

# as the README advises for large sheets (origami_jax.tuning): freed buffers stay in the heap,
# CHOLMOD's OpenBLAS runs this CPU's kernels, MKL's threads do not spin after PARDISO's calls
TUNED = tune_process()

THRESHOLDS = (1e-3, 1e-6, 1e-8, 1e-9)
SOLVERS = ("newton", "lbfgs", "dynamics")
SHARED = Path(__file__).resolve().parents[2] / "shared" / "patterns"


def cases(quick: bool):
    """(name, pattern, fold keyword arguments, exact reference shape or None, solvers)."""
    seed = patterns.seed_waterbomb()
    stiffness = {"stiffness": patterns.SEED_WATERBOMB_STIFFNESS}
    yield "seed_waterbomb", seed, stiffness, None, SOLVERS
    for n in (10,) if quick else (10, 30, 100):
        cp = patterns.miura_ori(n, n)
        extra = ("origami_simulator",) if n <= 30 else ()
        # the sparse solves (n >= 30) by the other installed backends, in the same run
        extra += tuple(f"newton_{b}" for b in hostsparse.available()[1:] if n >= 30)
        yield f"miura_{n}x{n}", cp, {}, rigid_fold(cp), SOLVERS + extra
    if quick:
        return
    cp = patterns.kresling(n=6, stories=2)
    yield "kresling_6x2", cp, {}, rigid_fold(cp), SOLVERS
    cp = patterns.yoshimura(6, 4)
    yield "yoshimura_6x4", cp, {}, rigid_fold(cp), SOLVERS
    yield from shared_cases("*.fold", "shared")


def shared_cases(glob: str, label: str, most: int | None = None):
    """The files under ../shared/patterns matching ``glob`` that load, as ``label:stem``
    cases with every solver (the first ``most`` only)."""
    paths = sorted(SHARED.rglob(glob)) if SHARED.is_dir() else []
    for path in paths[:most]:
        try:
            cp = io.load(path)
        except PatternError as err:
            print(f"skipped {path.relative_to(SHARED)}: {err}", file=sys.stderr)
            continue
        yield f"{label}:{path.stem}", cp, {}, None, SOLVERS


RATIOS = (1.0, 1e2, 1e4, 1e6, 1e8)


def svg_cases(quick: bool):
    """Every SVG file under ../shared/patterns that loads (the FOLD files are main cases)."""
    yield from shared_cases("*.svg", "svg", 2 if quick else None)


def stiffness_cases(quick: bool):
    """Miura-ori 10 x 10 at axial : crease stiffness ratios 1 to 1e8 (facets 20x the crease)."""
    cp = patterns.miura_ori(10, 10)
    exact = rigid_fold(cp)
    for ratio in RATIOS[:2] if quick else RATIOS:
        stiffness = {"axial": 1.0, "facet": 20.0 / ratio, "crease": 1.0 / ratio}
        yield f"miura_10x10_ratio_{ratio:.0e}", cp, {"stiffness": stiffness}, exact, SOLVERS


def file_cases(quick: bool):
    """Every SVG and FOLD file under ../shared/patterns, with the defaults (Newton)."""
    if not SHARED.is_dir():
        return
    for path in sorted(SHARED.rglob("*")):
        if path.suffix.lower() not in (".svg", ".fold"):
            continue
        name = str(path.relative_to(SHARED))
        t0 = time.perf_counter()
        try:
            cp = io.load(path)
        except PatternError as err:
            print(f"{name}: does not load: {err}", file=sys.stderr)
            continue
        yield name, cp, {"load_time_s": time.perf_counter() - t0}, None, ("newton",)
        if quick:
            return


PARTS = {
    # part: (cases, file prefix, plots, seconds per solve unless --max-time)
    "main": (cases, "", True, 120.0),
    "stiffness": (stiffness_cases, "stiffness_", False, 30.0),
    "files": (file_cases, "files_", False, 120.0),
    "svg": (svg_cases, "svg_", True, 30.0),
    "batch": (None, "batch_", True, None),  # benchmarks/batch.py
    "linear": (None, "linear_", True, None),  # benchmarks/linear.py
    "extreme": (None, "extreme_", True, None),  # benchmarks/extreme.py
}


def solver_object(name: str):
    if name == "origami_simulator":
        return origami_simulator()
    return "newton" if name.startswith("newton_") else name


def host_backend(name: str):
    """``hostsparse.using`` the backend that a ``newton_<backend>`` label names."""
    if name.startswith("newton_"):
        return hostsparse.using(name.removeprefix("newton_"))
    return contextlib.nullcontext()


# solves faster than this (s) are timed as the median of REPEATS runs
FAST, REPEATS = 1.0, 7


def median_time(cp, kwargs: dict, max_iter: int | None = None) -> float:
    if max_iter is not None:
        kwargs = dict(kwargs, max_iter=max_iter)
    return float(np.median([fold(cp, **kwargs).wall_time for _ in range(REPEATS)]))


def first_at(history: dict, key: str, threshold: float, column: str) -> float:
    """``column`` (wall_time or iteration) of the first sample at or below ``threshold``."""
    hit = np.flatnonzero(history[key] <= threshold)
    return float(history[column][hit[0]]) if len(hit) else float("nan")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small cases only")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    parser.add_argument("--solvers", default=None, help="only these (comma-separated names)")
    parser.add_argument("--tol", type=float, default=1e-10, help="grad_norm_rel tolerance")
    parser.add_argument(
        "--max-time", type=float, default=None, help="seconds per solve (120; sweep 30)"
    )
    parser.add_argument(
        "--part", choices=["all", *PARTS], default="all", help="main scenes, stiffness sweep"
    )
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    device = jax.devices()[0]
    machine = (
        f"{platform.machine()}, {usable_cores()} cores, jax {jax.__version__}, "
        f"device {device.platform}: {device.device_kind}, "
        f"CPU {cpu_name()}, sparse Newton solves: {hostsparse.backend_details()}, "
        f"process tuning (origami_jax.tuning): {TUNED}"
    )
    only = None if args.solvers is None else set(args.solvers.split(","))
    if args.part == "all":
        # one process per part: a single process compiling every part's shapes ran out of
        # memory mappings (LLVM "Cannot allocate memory" at the 65,530 of vm.max_map_count)
        argv = list(sys.argv[1:] if argv is None else argv)
        for part in PARTS:
            code = subprocess.call([sys.executable, __file__, *argv, "--part", part])
            if code:
                return code
        return 0
    for part, (make_cases, prefix, with_plots, max_time) in PARTS.items():
        if args.part != part:
            continue
        max_time = max_time if args.max_time is None else args.max_time
        if part in ("batch", "linear", "extreme"):  # their own scripts, beside this one
            module = __import__(part)
            module.main(out, quick=args.quick)
            continue
        if part == "files":
            summary = run_files(make_cases(args.quick), max_time)
            if summary:
                write_csv(out / f"{prefix}summary.csv", summary)
                table = files_markdown(summary, machine)
                (out / f"{prefix}results.md").write_text(table)
                print(table)
                try:
                    files_plot(summary, out / f"{prefix}errors.png")
                except ImportError:
                    print("matplotlib not installed: no plot", file=sys.stderr)
            continue
        summary, history_rows, plots = run_cases(make_cases(args.quick), args, only, max_time)
        write_csv(out / f"{prefix}summary.csv", summary)
        write_csv(out / f"{prefix}history.csv", history_rows)
        table = markdown(summary, machine)
        (out / f"{prefix}results.md").write_text(table)
        print(table)
        if with_plots:
            try:
                plot(plots, out)
            except ImportError:
                print(
                    "matplotlib not installed: no plots (pip install '.[bench]')", file=sys.stderr
                )
    return 0


def run_cases(case_list, args, only, max_time: float) -> tuple[list, list, dict]:
    """Fold every case with each of its solvers: summary rows, history rows, plot series."""
    summary, history_rows, plots = [], [], {}
    for name, cp, kwargs, reference, solvers in case_list:
        for solver in solvers:
            if only is not None and solver not in only:
                continue
            with host_backend(solver):  # newton_<backend>: all its folds by that backend
                common = dict(solver=solver_object(solver), tol=args.tol, **kwargs)
                first = fold(cp, max_iter=0, **common)  # compiles, runs nothing
                run = dict(reference_positions=reference, max_time=max_time, max_iter=10**9)
                r = fold(cp, **run, **common)
                wall_time = r.wall_time
                if wall_time < FAST:  # median of several runs: one is too noisy
                    wall_time = median_time(cp, dict(run, **common))
                plain = None
                if solver.startswith("newton"):  # resolve its few iterations: one sample each
                    r = fold(cp, record_every=1, **run, **common)
                    if wall_time < FAST:  # the sample round trips would dominate: see below
                        plain = functools.partial(median_time, cp, dict(run, **common))
                row = {
                    "case": name,
                    "solver": solver,
                    "vertices": cp.mesh.num_vertices,
                    "converged": r.converged,
                    "status": r.status.name,
                    "iterations": r.iterations,
                    "compile_time_s": first.compile_time,
                    "wall_time_s": wall_time,
                    "fold_angle_error_max": r.fold_angle_error_max,
                    "strain_max": r.strain_max,
                    "energy": r.energy,
                    "grad_norm_rel": r.grad_norm_rel,
                    "shape_error": r.shape_error if r.shape_error is not None else float("nan"),
                }
                key = "grad_norm_rel" if reference is None else "fold_angle_error_max"
                for t in THRESHOLDS:
                    row[f"time_to_{t:g}_s"] = first_at(r.history, key, t, "wall_time")
                    row[f"iterations_to_{t:g}"] = first_at(r.history, key, t, "iteration")
                    k = row[f"iterations_to_{t:g}"]
                    if plain is not None and np.isfinite(k):
                        # a fast solve's per-iteration samples cost more than its iterations:
                        # time a plain solve stopped after exactly that many iterations instead
                        row[f"time_to_{t:g}_s"] = plain(int(k))
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
                plots.setdefault(name.replace(":", "_"), []).append((solver, r.history))
                print(
                    f"{name:16s} {solver:17s} {r.iterations:7d} it  "
                    f"compile {first.compile_time:6.2f} s  run {r.wall_time:8.4f} s  "
                    f"err {r.fold_angle_error_max:.2e}  "
                    f"{'converged' if r.converged else r.reason}",
                    flush=True,
                )

    return summary, history_rows, plots


OS_FIDELITY = SHARED.parent / "reference" / "origami-simulator-fidelity.tsv"


def origami_simulator_rows() -> dict[str, dict]:
    """Origami Simulator's results on the shared files (its defaults, 20,000 steps), from
    ../shared/reference/origami-simulator-fidelity.tsv, by file under origami-simulator/."""
    if not OS_FIDELITY.is_file():
        return {}
    lines = [ln for ln in OS_FIDELITY.read_text().splitlines() if ln and not ln.startswith("#")]
    head = lines[0].split("\t")
    out = {}
    for line in lines[1:]:
        row = dict(zip(head, line.split("\t"), strict=False))
        if row.get("system") == "origami_simulator_20k":
            out["origami-simulator/" + row["file"]] = row
    return out


def run_files(case_list, max_time: float) -> list[dict]:
    """Fold each file once with the defaults (compile timed apart): one summary row each,
    beside Origami Simulator's figures where ../shared/reference has them."""
    theirs = origami_simulator_rows()
    rows = []
    for name, cp, extra, _, _ in case_list:
        first = fold(cp, max_iter=0)
        r = fold(cp, max_time=max_time)
        os_row = theirs.get(name, {})
        rows.append(
            {
                "file": name,
                "vertices": cp.num_vertices,
                "faces": len(cp.faces),
                "mesh_vertices": cp.mesh.num_vertices,
                "pre_folded_start": cp.start is not None,
                "path": r.path,
                "load_time_s": extra["load_time_s"],
                "compile_time_s": first.compile_time,
                "wall_time_s": r.wall_time,
                "iterations": r.iterations,
                "status": r.status.name,
                "grad_norm_rel": r.grad_norm_rel,
                "fold_angle_error_mean_deg": float(np.degrees(r.fold_angle_error_mean)),
                "fold_angle_error_max_deg": float(np.degrees(r.fold_angle_error_max)),
                "strain_max": r.strain_max,
                "through_pi": len(r.through_pi),
                "collapsed": len(r.collapsed),
                "intersections": len(r.intersections),
                "os_error_mean_deg": float(os_row.get("err_mean_deg", "nan")),
                "os_error_max_deg": float(os_row.get("err_max_deg", "nan")),
                "os_wrong_side": float(os_row.get("wrong_side_1e-6", "nan")),
                "os_intersections": float(os_row.get("intersections_1e-6", "nan")),
                "os_run_s": float(os_row.get("run_s", "nan")),
            }
        )
        print(f"{name:45s} {r.iterations:6d} it  {r.wall_time:7.2f} s  {r.reason}", flush=True)
    return rows


def files_markdown(rows: list[dict], machine: str) -> str:
    head = ["file", "vertices", "path", "compile (s)", "fold (s)", "iterations", "status"]
    head += ["mean error (deg)", "max error (deg)", "through pi", "collapsed", "intersecting"]
    head += ["OS mean (deg)", "OS max (deg)", "OS wrong side", "OS intersecting", "OS (s)"]
    clean = [
        r for r in rows if r["status"] == "CONVERGED" and not (r["through_pi"] or r["collapsed"])
    ]
    lines = [
        f"Measured {time.strftime('%Y-%m-%d')} on {machine}; float64, defaults (Newton, "
        "stiffness axial 1 / facet 0.02 / crease 0.001, full fold; the path from flat where a "
        "crease folds fully, 'continuation', else 'direct'). Errors over the driven creases, "
        "degrees; 'through pi': creases more than 1e-5 rad past +-pi; 'collapsed': triangles "
        "below 1e-6 of their flat area; 'intersecting': pairs of triangles sharing no vertex "
        "that cross deeper than 1e-6 of the sheet's diameter. OS: Origami Simulator at its "
        "defaults after 20,000 steps, from ../shared/reference/origami-simulator-fidelity.tsv "
        "(its 'wrong side' and 'intersecting' at the same 1e-6 depth; its time is its steps' "
        "wall time, ours the solve's, compile apart).",
        "",
        f"Files: {len(rows)} loaded, "
        f"{sum(r['status'] == 'CONVERGED' for r in rows)} converged, "
        f"{len(clean)} converged with no crease through pi and no collapsed triangle, "
        f"{sum(not r['intersections'] for r in clean)} of those with no intersecting faces.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]

    def g(v, fmt=".3g"):
        return "" if v != v else format(v, fmt)  # NaN: no Origami Simulator row

    for r in rows:
        cells = [
            r["file"],
            str(r["vertices"]),
            r["path"],
            f"{r['compile_time_s']:.2f}",
            f"{r['wall_time_s']:.3g}",
            str(r["iterations"]),
            r["status"].lower().replace("_", " "),
            g(r["fold_angle_error_mean_deg"]),
            g(r["fold_angle_error_max_deg"]),
            str(r["through_pi"]),
            str(r["collapsed"]),
            str(r["intersections"]),
            g(r["os_error_mean_deg"]),
            g(r["os_error_max_deg"]),
            g(r["os_wrong_side"], ".0f"),
            g(r["os_intersections"], ".0f"),
            g(r["os_run_s"]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def files_plot(rows: list[dict], out: Path) -> None:
    """Mean fold-angle error per file, ours beside Origami Simulator's (log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [r["file"].split("/")[-1] for r in rows]
    floor = 1e-12
    ours = [max(r["fold_angle_error_mean_deg"], floor) for r in rows]
    theirs = [max(r["os_error_mean_deg"], floor) for r in rows]
    y = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(8, 0.28 * len(rows) + 1.5))
    ax.barh(y - 0.2, ours, 0.4, label="origami_jax (defaults)")
    ax.barh(y + 0.2, theirs, 0.4, label="Origami Simulator (20,000 steps)")
    ax.set_xscale("log")
    ax.set_yticks(y, names, fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel(f"mean fold-angle error (deg; {floor:g} shown for exact)")
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


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
    head += ["iterations to 1e-06", "final fold-angle error (rad)", "strain_max"]
    head += ["grad_norm_rel", "shape_error", "to 1e-06 vs newton"]
    lines = [
        f"Measured {time.strftime('%Y-%m-%d')} on {machine}; float64. Columns 'to 1e-3' etc.:"
        " wall time (s, compile excluded) until fold_angle_error_max (rad) first fell to that"
        " value, or, for patterns without an exact shape (the seed's scene, shared files),"
        " grad_norm_rel; '-' never. 'vs newton': that time over Newton's on the same case."
        " Solves under a second: median of 7 runs (Newton's 'to' times: of plain solves"
        " stopped at that iteration), so differences of a few percent there are noise.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    newton = {r["case"]: r["time_to_1e-06_s"] for r in rows if r["solver"] == "newton"}
    for r in rows:
        status = "" if r["converged"] else f" ({r['status'].lower().replace('_', ' ')})"
        base = newton.get(r["case"], float("nan"))
        cells = [
            r["case"],
            r["solver"],
            str(r["vertices"]),
            f"{r['iterations']}{status}",
            f"{r['compile_time_s']:.2f}",
            f"{r['wall_time_s']:.4g}",
        ]
        cells += [fmt(r[f"time_to_{t:g}_s"]) for t in THRESHOLDS]
        iters = r["iterations_to_1e-06"]
        cells += [
            "-" if iters != iters else f"{int(iters)}",
            fmt(r["fold_angle_error_max"]),
            fmt(r["strain_max"]),
            fmt(r["grad_norm_rel"]),
            fmt(r["shape_error"]),
            fmt(r["time_to_1e-06_s"] / base) if base == base and base > 0 else "-",
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
