"""Scale: Newton folds a Miura-ori of 1,000 to 100,000 vertices, each in a fresh process.

    python benchmarks/scale.py                       # n = 31, 55, 100, 173, 316; results written
    python benchmarks/scale.py --sizes 31 55 --no-write   # a quick look, nothing written
    python benchmarks/scale.py --backend cholmod --repeat 3

Folds ``patterns.miura_ori(n, n)`` ((n + 1)^2 vertices: about 1,000, 3,000, 10,000, 30,000 and
100,000) at the defaults: Newton, float64, sparse above 200 vertices with the best installed
host backend (or ``--backend``), the default tolerance, the processes tuned as the other
benchmarks are (:func:`origami_jax.tuning.tune_process`). Each fold runs in a process of its
own, so that its peak resident memory (``ru_maxrss``, read right after the fold) is its own;
the peak includes the pattern, its exact folded shape (:func:`~origami_jax.kinematics.rigid_fold`,
the reference of ``shape_error``), JAX and the compile. Bytes per vertex: the slope of a
least-squares line through peak memory against vertices (its intercept is the fixed cost).

Recorded per size: vertices, iterations, compile time (``result.compile_time``), solve time
(``result.wall_time``: compile excluded, to the default tolerance), the time to 1e-8 rad (the
solve time until ``fold_angle_error_max`` first fell to 1e-8: see :func:`time_to_target`), the
whole ``fold()`` call (also the host's set-up: the Hessian's layout and order),
``fold_angle_error_max`` and ``shape_error`` at the end, and each solve's split per iteration:

* **factorization** and **solve**: seconds inside the backend's analysis plus numeric
  factorizations, and its triangular solves, timed inside the host callbacks by
  :func:`origami_jax.solvers.hostsparse.timings` (an opt-in clock in the callbacks);
* **host other**: the rest of the time inside the callbacks (checks, copies, the pattern's
  look-up);
* **transfer**: what a host callback with the same operands and results costs around the
  Python function (XLA to Python and back: the FFI call, ``pure_callback``'s ``device_put`` of
  the operands, the results' copy back), measured after the fold in the same process as the
  median of a compiled loop of no-op callbacks with the shapes of ``factor_solve``'s (the
  matrix's CSR pattern and values, the right-hand side) and ``resolve``'s, times the calls made;
* **JAX**: the rest of the solve time (the compiled iterations: energy, gradient, the element
  Hessians and their assembly, the line search).

Writes ``scale_summary.csv``, ``scale_results.md`` and (with matplotlib) ``scale.png`` (peak
memory and times against vertices, log-log) in ``benchmarks/results``. The machine is shared:
times vary with other users' load (compare within one run); peak memory does not.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"
SIZES = (31, 55, 100, 173, 316)
# the targets (issue 44, item 3): the 316 x 316 fold and the 100 x 100 fold
TARGETS = {316: (20.0, 8.0), 100: (1.0, None)}  # n: (solve s, peak GiB)
ANGLE_TARGET = 1e-8


def _resident() -> int:
    """This process's resident memory now, bytes (Linux; 0 elsewhere)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def _peak() -> int:
    """This process's peak resident memory so far, bytes (``ru_maxrss``: KiB on Linux)."""
    import resource

    scale = 1 if sys.platform == "darwin" else 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale


def _faults() -> int:
    """This process's minor page faults so far (fresh memory touched)."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


def _callback_seconds(unknowns: int, entries: int, calls: int = 10, runs: int = 5):
    """Seconds per call of a no-op host callback with ``factor_solve``'s operands and results
    (CSR pattern and values, right-hand side, flag) and with ``resolve``'s (token, right-hand
    side): medians of ``runs`` compiled loops of ``calls`` callbacks each."""
    import time

    import jax
    import jax.numpy as jnp
    import numpy as np

    indptr = jnp.zeros(unknowns + 1, jnp.int32)
    indices = jnp.zeros(entries, jnp.int32)
    values = jnp.ones(entries)
    rhs = jnp.ones(unknowns)

    def factor_solve(indptr, indices, values, b, active):
        return np.zeros_like(b), np.asarray(True), np.asarray(1, np.int32)

    def resolve(token, b):
        return np.zeros_like(b)

    out = (
        jax.ShapeDtypeStruct(rhs.shape, rhs.dtype),
        jax.ShapeDtypeStruct((), jnp.bool_),
        jax.ShapeDtypeStruct((), jnp.int32),
    )

    @jax.jit
    def first(values, b):
        def body(_, b):
            x, _, _ = jax.pure_callback(
                factor_solve, out, indptr, indices, values, b, True, vmap_method="sequential"
            )
            return b + x

        return jax.lax.fori_loop(0, calls, body, b)

    @jax.jit
    def second(b):
        def body(_, b):
            x = jax.pure_callback(resolve, out[0], jnp.int32(1), b, vmap_method="sequential")
            return b + x

        return jax.lax.fori_loop(0, calls, body, b)

    def median(fn, *args):
        jax.block_until_ready(fn(*args))  # compiled
        times = []
        for _ in range(runs):
            start = time.perf_counter()
            jax.block_until_ready(fn(*args))
            times.append(time.perf_counter() - start)
        return statistics.median(times) / calls

    return median(first, values, rhs), median(second, rhs)


def time_to_target(cp, r, runs: int = 5) -> tuple[int | None, float | None]:
    """``(k, seconds)``: the first iteration whose fold angle error is at most
    ``ANGLE_TARGET`` and the solve time to it (compile excluded), or ``(None, None)``. Where the
    fold's history sampled the iteration before ``k`` too (an iteration per chunk: large
    sheets), its time there; else ``k`` from a fold that samples every iteration, and the median
    of ``runs`` plain folds stopped after ``k`` iterations (as ``benchmarks/run.py`` times its
    "to 1e-8" columns: no per-iteration round trip counted)."""
    import numpy as np

    from origami_jax import fold

    def first(history):
        hit = np.flatnonzero(history["fold_angle_error_max"] <= ANGLE_TARGET)
        return (None, None) if not hit.size else (int(hit[0]), history["iteration"])

    at, iterations = first(r.history)
    if at is None:
        return None, None
    k = int(iterations[at])
    if at > 0 and int(iterations[at - 1]) == k - 1:
        return k, float(r.history["wall_time"][at])
    at, iterations = first(fold(cp, record_every=1).history)
    k = int(iterations[at])
    return k, statistics.median(fold(cp, max_iter=k).wall_time for _ in range(runs))


def one(n: int, backend: str | None) -> dict:
    """Fold the Miura-ori n x n in this process (a fresh one: see ``main``) and measure it."""
    import time

    os.environ.setdefault("JAX_ENABLE_X64", "1")
    import jax

    jax.config.update("jax_enable_x64", True)
    from origami_jax import fold, patterns
    from origami_jax.kinematics import rigid_fold
    from origami_jax.solvers import hostsparse
    from origami_jax.tuning import tune_process

    tune_process()  # as the other benchmarks and the command line (origami_jax.tuning)
    start = time.perf_counter()
    cp = patterns.miura_ori(n, n)
    reference = rigid_fold(cp)
    built = time.perf_counter() - start
    before = _resident()
    faults = _faults()
    backend = backend or hostsparse.backend()
    with hostsparse.using(backend), hostsparse.timings() as host:
        details = hostsparse.backend_details()
        start = time.perf_counter()
        r = fold(cp, reference_positions=reference)
        call = time.perf_counter() - start
    peak, faults = _peak(), _faults() - faults
    host = dict(host)
    with hostsparse.using(backend):
        to_iteration, to_seconds = time_to_target(cp, r)
    first = second = 0.0
    if host["factor_solve_calls"]:  # sparse (above 200 vertices)
        first, second = _callback_seconds(int(host["unknowns"]), int(host["entries"]))
    transfer = first * host["factor_solve_calls"] + second * host["resolve_calls"]
    return {
        "n": n,
        "vertices": cp.mesh.num_vertices,
        "backend": details,
        "unknowns": int(host["unknowns"]),
        "stored_entries": int(host["entries"]),
        "iterations": int(r.iterations),
        "converged": bool(r.converged),
        "compile_s": r.compile_time,
        "solve_s": r.wall_time,
        "to_1e-8_iteration": to_iteration,
        "to_1e-8_s": to_seconds,
        "fold_call_s": call,
        "pattern_s": built,
        "fold_angle_error_max": float(r.fold_angle_error_max),
        "shape_error": float(r.shape_error),
        "peak_rss_bytes": peak,
        "rss_before_fold_bytes": before,
        "page_faults": faults,
        "factor_solve_calls": int(host["factor_solve_calls"]),
        "resolve_calls": int(host["resolve_calls"]),
        "analyses": int(host["analyses"]),
        "factorizations": int(host["factorizations"]),
        "solves": int(host["solves"]),
        "analyse_s": host["analyse"],
        "factor_s": host["factor"],
        "triangular_solve_s": host["solve"],
        "host_other_s": host["callbacks"] - host["analyse"] - host["factor"] - host["solve"],
        "transfer_s": transfer,
        "transfer_per_factor_solve_s": first,
        "transfer_per_resolve_s": second,
        "jax_s": r.wall_time - host["callbacks"] - transfer,
    }


def run_one(n: int, backend: str | None) -> dict:
    """:func:`one` in a fresh Python process (its own peak memory)."""
    command = [sys.executable, __file__, "--one", str(n)]
    if backend:
        command += ["--backend", backend]
    out = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    if out.returncode != 0:
        print(out.stdout + out.stderr, file=sys.stderr)
        return {"n": n, "failed": f"exit status {out.returncode}"}
    return json.loads(out.stdout.strip().splitlines()[-1])


def linear_fit(x: list[float], y: list[float]) -> tuple[float, float]:
    """Least-squares ``y = a + b x``: ``(a, b)``."""
    mx, my = statistics.fmean(x), statistics.fmean(y)
    b = sum((u - mx) * (v - my) for u, v in zip(x, y, strict=True)) / sum((u - mx) ** 2 for u in x)
    return my - b * mx, b


def log_slope(x: list[float], y: list[float]) -> float:
    """The slope of ``log y`` against ``log x`` (least squares): the growth's exponent."""
    import math

    return linear_fit([math.log(u) for u in x], [math.log(v) for v in y])[1]


def per_iteration(row: dict, key: str) -> float:
    return row[key] / max(row["iterations"], 1)


def report(rows: list[dict], machine: str) -> str:
    """The markdown of ``scale_results.md``."""
    gib = 2.0**30
    v = [r["vertices"] for r in rows]
    # a line needs two sizes: with one, no fixed part is taken off the bytes per vertex
    fitted = len(set(v)) >= 2
    intercept, slope = linear_fit(v, [r["peak_rss_bytes"] for r in rows]) if fitted else (0, 0)
    big = rows[-3:] if len(rows) >= 3 else rows
    vb = [r["vertices"] for r in big]
    lines = [
        f"# Scale: Miura-ori to 100,000 vertices ({datetime.date.today().isoformat()})",
        "",
        f"Machine: {machine}. `python benchmarks/scale.py`: Newton at the defaults, float64, "
        "each fold in a fresh process; solve time excludes compiling. The machine is shared "
        "with other users' work: times are indicative (compare within one run), peak memory "
        "is not affected.",
        "",
        "| n x n | vertices | iterations | compile s | solve s | to 1e-8 rad: s (iteration) | "
        "`fold()` s | fold angle error max (rad) | shape error | peak GiB | bytes / vertex |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        per_vertex = (r["peak_rss_bytes"] - intercept) / r["vertices"]
        to = "-"
        if r["to_1e-8_s"] is not None:
            to = f"{r['to_1e-8_s']:.2f} ({r['to_1e-8_iteration']})"
        lines.append(
            f"| {r['n']} x {r['n']} | {r['vertices']:,} | {r['iterations']} | "
            f"{r['compile_s']:.1f} | {r['solve_s']:.2f} | {to} | {r['fold_call_s']:.1f} | "
            f"{r['fold_angle_error_max']:.1e} | {r['shape_error']:.1e} | "
            f"{r['peak_rss_bytes'] / gib:.2f} | {per_vertex:,.0f} |"
        )
    memory = (
        f"Peak resident memory against vertices, least squares: **{slope:,.0f} bytes per "
        f"vertex** plus {intercept / gib:.2f} GiB (JAX, the compiled solver, the process). The "
        "last column: each fold's peak less that fixed part, per vertex."
        if fitted
        else "One size: no line through peak memory against vertices; the last column is the "
        "whole peak per vertex."
    )
    lines += [
        "",
        memory + " `fold()` s: the whole call (compile, solve, and the host's set-up of the "
        "Hessian's layout and order).",
        "",
        "Per iteration (seconds; the split of the solve time, see the script's docstring: "
        "factorization = the backend's analysis and numeric factorizations, solve = its "
        "triangular solves, host other = the rest inside the callbacks, transfer = around the "
        "callbacks, JAX = the compiled rest):",
        "",
        "| vertices | unknowns | stored entries | factorizations | solve s / iteration | "
        "factorization | triangular solves | host other | transfer | JAX | s / factorization |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['vertices']:,} | {r['unknowns']:,} | {r['stored_entries']:,} | "
            f"{r['factorizations']} | {per_iteration(r, 'solve_s'):.3f} | "
            f"{per_iteration(r, 'analyse_s') + per_iteration(r, 'factor_s'):.3f} | "
            f"{per_iteration(r, 'triangular_solve_s'):.3f} | "
            f"{per_iteration(r, 'host_other_s'):.4f} | {per_iteration(r, 'transfer_s'):.4f} | "
            f"{per_iteration(r, 'jax_s'):.3f} | "
            f"{r['factor_s'] / max(r['factorizations'], 1):.3f} |"
        )
    if len(big) >= 2:
        grows = {
            "solve time per iteration": [per_iteration(r, "solve_s") for r in big],
            "a factorization": [r["factor_s"] / max(r["factorizations"], 1) for r in big],
            "JAX per iteration": [per_iteration(r, "jax_s") for r in big],
            "peak memory": [r["peak_rss_bytes"] for r in big],
        }
        text = ", ".join(f"{k} V^{log_slope(vb, y):.2f}" for k, y in grows.items())
        lines += [
            "",
            f"Growth with vertices V over the {len(big)} largest (log-log slopes): {text}.",
        ]
    lines += ["", "Targets (issue 44, item 3):", ""]
    by_n = {r["n"]: r for r in rows}
    for n, (seconds, memory) in TARGETS.items():
        r = by_n.get(n)
        if r is None:
            continue
        to = r["to_1e-8_s"]
        met = [
            f"to 1e-8 rad in {to:.2f} s, to the default tolerance in {r['solve_s']:.2f} s "
            f"(target {seconds:g} s: {'met' if to <= seconds else 'not met'})"
            if to is not None
            else "1e-8 rad not reached (not met)"
        ]
        if memory is not None:
            ok = r["peak_rss_bytes"] / gib <= memory
            met.append(
                f"peak {r['peak_rss_bytes'] / gib:.2f} GiB (target {memory:g} GB: "
                f"{'met' if ok else 'not met'})"
            )
        ok = r["converged"] and r["fold_angle_error_max"] <= ANGLE_TARGET
        met.append(
            f"fold angle error {r['fold_angle_error_max']:.1e} rad (target {ANGLE_TARGET:g}: "
            f"{'met' if ok else 'not met'})"
        )
        lines.append(f"- Miura-ori {n} x {n}: " + "; ".join(met) + ".")
    return "\n".join(lines) + "\n"


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = [r["vertices"] for r in rows]
    # a line needs two sizes: with one, no fixed part is taken off the bytes per vertex
    fitted = len(set(v)) >= 2
    intercept, slope = linear_fit(v, [r["peak_rss_bytes"] for r in rows]) if fitted else (0, 0)
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    left.loglog(v, [r["peak_rss_bytes"] / 2**30 for r in rows], "o-", label="peak RSS")
    left.loglog(v, [(intercept + slope * u) / 2**30 for u in v], "--", label="linear fit")
    left.set(xlabel="vertices", ylabel="GiB", title="peak resident memory")
    left.legend()
    series = {
        "solve time": "solve_s",
        "factorization": "factor_s",
        "triangular solves": "triangular_solve_s",
        "JAX": "jax_s",
        "transfer": "transfer_s",
    }
    for label, key in series.items():
        right.loglog(v, [per_iteration(r, key) for r in rows], "o-", label=label)
    right.loglog(v, [r["compile_s"] for r in rows], "s:", label="compile (once)")
    right.set(xlabel="vertices", ylabel="s per iteration", title="time per Newton iteration")
    right.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    parser.add_argument("--backend", choices=("pardiso", "cholmod", "superlu"), default=None)
    parser.add_argument("--repeat", type=int, default=1, help="folds per size (median kept)")
    parser.add_argument("--no-write", action="store_true", help="print only")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # the child process
    args = parser.parse_args()
    if args.one is not None:
        print(json.dumps(one(args.one, args.backend)))
        return
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import jax
    from cores import cpu_name, usable_cores

    rows = []
    for n in args.sizes:
        runs = [run_one(n, args.backend) for _ in range(args.repeat)]
        done = [r for r in runs if "failed" not in r]
        if not done:
            print(f"{n} x {n}: {runs[0]['failed']}")
            continue
        row = sorted(done, key=lambda r: r["solve_s"])[len(done) // 2]  # the median fold
        row["solve_s_runs"] = " ".join(f"{r['solve_s']:.2f}" for r in done)
        rows.append(row)
        print(
            f"{n} x {n}: {row['vertices']} vertices, {row['iterations']} iterations, compile "
            f"{row['compile_s']:.1f} s, solve {row['solve_s_runs']} s (to 1e-8 rad "
            f"{row['to_1e-8_s']} s), error "
            f"{row['fold_angle_error_max']:.1e} rad, peak {row['peak_rss_bytes'] / 2**30:.2f} "
            f"GiB, per iteration: factor {per_iteration(row, 'factor_s'):.3f} s, JAX "
            f"{per_iteration(row, 'jax_s'):.3f} s",
            flush=True,
        )
    if not rows:
        return
    machine = (
        f"{platform.machine()}, {usable_cores()} cores (shared), jax {jax.__version__}, CPU "
        f"{cpu_name()}, host backend {rows[0]['backend']}"
    )
    table = report(rows, machine)
    print(table)
    if args.no_write:
        return
    OUT.mkdir(parents=True, exist_ok=True)
    with open(OUT / "scale_summary.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (OUT / "scale_results.md").write_text(table)
    try:
        plot(rows, OUT / "scale.png")
    except ImportError:
        print("matplotlib not installed: no plot (pip install '.[bench]')")


if __name__ == "__main__":
    main()
