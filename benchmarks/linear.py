"""Newton's linear systems: sparse direct Cholesky against preconditioned conjugate gradients.

    python benchmarks/linear.py            # or: python benchmarks/run.py --part linear
    python benchmarks/linear.py --quick    # Miura-ori 30 x 30 only

The solvers issue asks for the Newton step to be "solved by a sparse direct factorization or a
preconditioned Krylov method, whichever measures faster". This records every system that
Newton's host path factors while folding Miura-ori 30 x 30 and 100 x 100 (each iteration's
matrix, including exact Hessians that turn out not positive definite, with the Newton step's
right-hand side) and solves each again three ways:

* ``direct_<backend>``: what Newton does (:func:`origami_jax.solvers.hostsparse.factor_solve`),
  best of 3, factorization and solve, by every installed backend (PARDISO, CHOLMOD, SuperLU;
  the first is the one Newton uses, and the reference for the others' errors);
* ``pcg_lagged``: conjugate gradients preconditioned by the previous system's factorization
  (the cheapest preconditioner that knows the sheet's stiff and soft directions: one
  triangular solve pair per iteration, no factorization);
* ``pcg_block_jacobi``: conjugate gradients preconditioned by the inverted 3 x 3 vertex blocks.

Each PCG runs to a relative residual of 1e-8 (the iterations to 1e-3 are read off the same
run), at most ``MAX_ITER`` iterations; a direction of negative curvature (a matrix that is not
positive definite) stops it. Times are wall times of NumPy/SciPy code on this machine's
cores; compare the methods by their ratios in the same run. Writes ``linear_summary.csv``,
``linear_results.md`` and (with matplotlib) ``linear_systems.png`` in ``benchmarks/results``.
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import statistics
import time
from pathlib import Path

os.environ.setdefault("JAX_ENABLE_X64", "1")

import jax  # noqa: E402
from cores import cpu_name, usable_cores  # noqa: E402 (benchmarks/, the script's folder)

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402

from origami_jax import fold, patterns  # noqa: E402
from origami_jax.solvers import hostsparse  # noqa: E402
from origami_jax.tuning import tune_process  # noqa: E402

# the settings Newton's solves run with in the CLI and benchmarks (origami_jax.tuning); the
# OpenBLAS kernels before cvxopt is first loaded
TUNED = tune_process()

MAX_ITER = {"pcg_lagged": 300, "pcg_block_jacobi": 3000}
TOLS = (1e-3, 1e-8)
DIRECT = tuple(f"direct_{backend}" for backend in ("pardiso", "cholmod", "superlu"))


def column(tol: float) -> str:
    """The summary's column of the iterations to ``tol``: ``iterations_to_1e-3``."""
    return "iterations_to_" + f"{tol:.0e}".replace("e-0", "e-")


def record_systems(n: int) -> tuple[list[tuple[sp.csr_matrix, np.ndarray]], object]:
    """Fold a Miura-ori n x n with Newton and keep every host-factored system (its upper
    triangle, as Newton assembles it, and the rhs)."""
    systems = []
    inner = hostsparse._factor_solve  # the host call behind factor_solve (Newton's only path)

    def recording(indptr, indices, data, rhs, keep):
        size = len(indptr) - 1
        matrix = sp.csr_matrix((np.array(data), np.array(indices), np.array(indptr)), (size, size))
        systems.append((matrix, np.array(rhs, np.float64).reshape(-1)))
        return inner(indptr, indices, data, rhs, keep)

    hostsparse._factor_solve = recording
    try:
        result = fold(patterns.miura_ori(n, n), solver="newton", tol=1e-10)
    finally:
        hostsparse._factor_solve = inner
    return systems, result


def direct(upper: sp.csr_matrix, rhs: np.ndarray, backend: str) -> tuple[np.ndarray | None, float]:
    """Newton's factorization and solve by ``backend``: (solution or None if not positive
    definite, s)."""
    best, x = np.inf, None
    with hostsparse.using(backend):
        for _ in range(3):
            t = time.perf_counter()
            x, ok, _ = hostsparse.factor_solve(upper.indptr, upper.indices, upper.data, rhs)
            best = min(best, time.perf_counter() - t)
    return (np.asarray(x) if bool(ok) else None), best


def pcg(matrix: sp.csr_matrix, rhs: np.ndarray, precondition, max_iter: int) -> dict:
    """Preconditioned conjugate gradients from zero: iterations to each of ``TOLS`` (relative
    residual), how it stopped, its solution and wall time."""
    t = time.perf_counter()
    x = np.zeros_like(rhs)
    r = rhs.copy()
    z = precondition(r)
    p = z.copy()
    rz = r @ z
    norm = np.linalg.norm(rhs)
    reached = {tol: None for tol in TOLS}
    status = "max_iter"
    for k in range(1, max_iter + 1):
        ap = matrix @ p
        curvature = p @ ap
        if not curvature > 0:
            status = "negative_curvature"
            break
        alpha = rz / curvature
        x += alpha * p
        r -= alpha * ap
        residual = np.linalg.norm(r) / norm
        for tol in TOLS:
            if reached[tol] is None and residual <= tol:
                reached[tol] = k
        if residual <= TOLS[-1]:
            status = "converged"
            break
        z = precondition(r)
        rz, rz_old = r @ z, rz
        p = z + (rz / rz_old) * p
    return {"x": x, "status": status, "reached": reached, "time_s": time.perf_counter() - t}


def block_jacobi(matrix: sp.csr_matrix):
    """``r -> D^-1 r`` with D the 3 x 3 diagonal vertex blocks of ``matrix``."""
    size = matrix.shape[0]
    coo = matrix.tocoo()
    same = coo.row // 3 == coo.col // 3
    blocks = np.zeros((size // 3, 3, 3))
    np.add.at(blocks, (coo.row[same] // 3, coo.row[same] % 3, coo.col[same] % 3), coo.data[same])
    inverse = np.linalg.inv(blocks)
    return lambda r: np.einsum("vij,vj->vi", inverse, r.reshape(-1, 3)).reshape(-1)


def measure(name: str, systems) -> list[dict]:
    """``systems``: (upper triangle, rhs) pairs; direct solves read the triangle as Newton's do,
    conjugate gradients multiply by the whole matrix."""
    rows, previous, release = [], None, None
    for index, (upper, rhs) in enumerate(systems):
        matrix = hostsparse.symmetric_matrix(upper.indptr, upper.indices, upper.data)
        base = {"pattern": name, "system": index, "unknowns": matrix.shape[0], "nnz": matrix.nnz}
        exact_x = None
        for backend in hostsparse.available():
            x, direct_time = direct(upper, rhs, backend)
            exact_x = x if backend == hostsparse.backend() else exact_x
            error = ""
            if x is not None and exact_x is not None:
                error = float(np.linalg.norm(x - exact_x) / np.linalg.norm(exact_x))
            rows.append(
                {
                    **base,
                    "method": f"direct_{backend}",
                    "status": "factored" if x is not None else "not_positive_definite",
                    **{column(tol): "" for tol in TOLS},
                    "time_s": direct_time,
                    "error_vs_direct": error,
                }
            )
        methods = {"pcg_block_jacobi": block_jacobi(matrix)}
        if previous is not None:
            methods["pcg_lagged"] = previous
        for method, precondition in methods.items():
            run = pcg(matrix, rhs, precondition, MAX_ITER[method])
            error = ""
            if exact_x is not None:
                error = float(np.linalg.norm(run["x"] - exact_x) / np.linalg.norm(exact_x))
            rows.append(
                {
                    **base,
                    "method": method,
                    "status": run["status"],
                    **{column(tol): run["reached"][tol] or "" for tol in TOLS},
                    "time_s": run["time_s"],
                    "error_vs_direct": error,
                }
            )
        if exact_x is not None:  # the next system's lagged preconditioner
            found = hostsparse._factor(upper.indptr, upper.indices, upper.data)
            if found is not None:
                if release is not None:
                    release()
                previous, release = found
        print(
            f"{name} system {index}: "
            + ", ".join(
                f"{r['method']} {r['status']} {r['time_s']:.3f} s"
                for r in rows
                if r["pattern"] == name and r["system"] == index
            ),
            flush=True,
        )
    return rows


def markdown(rows: list[dict], machine: str, folds: dict) -> str:
    lines = [
        f"# Newton's linear systems: direct against PCG ({time.strftime('%Y-%m-%d')})",
        "",
        f"Machine: {machine}. Every system Newton's host path factored while folding each "
        "pattern (`python benchmarks/linear.py`), solved again by each method; PCG to a "
        f"relative residual of 1e-8, at most {MAX_ITER['pcg_lagged']} iterations (lagged) or "
        f"{MAX_ITER['pcg_block_jacobi']} (block Jacobi).",
        "",
        "| pattern | unknowns | systems (not PD) | method | reached 1e-3 | reached 1e-8 "
        "| median iterations to 1e-3 / 1e-8 (runs that reached it) "
        "| median s per system | total s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name in dict.fromkeys(r["pattern"] for r in rows):
        mine = [r for r in rows if r["pattern"] == name]
        systems = [r for r in mine if r["method"] == f"direct_{hostsparse.backend()}"]
        failed = sum(r["status"] != "factored" for r in systems)
        for method in (*DIRECT, "pcg_lagged", "pcg_block_jacobi"):
            runs = [r for r in mine if r["method"] == method]
            if not runs:
                continue
            times = [r["time_s"] for r in runs]
            if method in DIRECT:
                reach = iters = "(exact)"
                reach8 = f"{len(runs) - failed} of {len(runs)} factored"
            else:
                hit = {tol: [r[column(tol)] for r in runs] for tol in TOLS}
                done = {tol: [k for k in hit[tol] if k != ""] for tol in TOLS}
                reach = f"{len(done[1e-3])} of {len(runs)}"
                reach8 = f"{len(done[1e-8])} of {len(runs)}"
                iters = " / ".join(
                    f"{statistics.median(done[tol]):.0f}" if done[tol] else "-" for tol in TOLS
                )
            lines.append(
                f"| {name} | {runs[0]['unknowns']} | {len(systems)} ({failed}) | {method} "
                f"| {reach} | {reach8} | {iters} | {statistics.median(times):.3f} "
                f"| {sum(times):.2f} |"
            )
    lines += ["", "Newton's folds that produced the systems:", ""]
    lines += [f"- {name}: {summary}" for name, summary in folds.items()]
    return "\n".join(lines) + "\n"


def plot(rows: list[dict], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r["pattern"] for r in rows))
    fig, axes = plt.subplots(1, len(names), figsize=(6 * len(names), 4.8), squeeze=False)
    for ax, name in zip(axes[0], names, strict=True):
        markers = {**dict(zip(DIRECT, "oDv", strict=True)), "pcg_lagged": "s"}
        for method, marker in {**markers, "pcg_block_jacobi": "^"}.items():
            runs = [r for r in rows if r["pattern"] == name and r["method"] == method]
            if not runs:
                continue
            ok = [r for r in runs if r["status"] in ("factored", "converged")]
            ax.semilogy([r["system"] for r in ok], [r["time_s"] for r in ok], marker, label=method)
            bad = [r for r in runs if r not in ok]
            if bad:
                ax.semilogy(
                    [r["system"] for r in bad], [r["time_s"] for r in bad], marker,
                    mfc="none", color=ax.lines[-1].get_color(), label=f"{method} (not solved)",
                )  # fmt: skip
        ax.set_title(f"{name}: seconds per Newton system")
        ax.set_xlabel("system (in the order Newton factored them)")
        ax.set_ylabel("wall time (s)")
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=3)
    fig.tight_layout()
    fig.savefig(out / "linear_systems.png", dpi=120)
    plt.close(fig)


def main(out: Path, quick: bool = False) -> None:
    out.mkdir(parents=True, exist_ok=True)
    machine = (
        f"{platform.machine()}, {usable_cores()} cores, jax {jax.__version__}, "
        f"CPU {cpu_name()}, Newton's direct solves: {hostsparse.backend_details()}, "
        f"process tuning (origami_jax.tuning): {TUNED}"
    )
    rows, folds = [], {}
    for n in (30,) if quick else (30, 100):
        name = f"miura_{n}x{n}"
        systems, result = record_systems(n)
        folds[name] = (
            f"{result.iterations} iterations, {len(systems)} systems, "
            f"fold_angle_error_max {result.fold_angle_error_max:.1e} rad"
        )
        rows += measure(name, systems)
    with open(out / "linear_summary.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    table = markdown(rows, machine, folds)
    (out / "linear_results.md").write_text(table)
    print(table)
    try:
        plot(rows, out)
    except ImportError:
        print("matplotlib not installed: no plot (pip install '.[bench]')")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="Miura-ori 30 x 30 only")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results"))
    args = parser.parse_args()
    main(Path(args.out), quick=args.quick)
