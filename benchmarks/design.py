"""Inverse design: the cost of one implicit gradient against one forward solve, and its accuracy.

    python benchmarks/design.py            # (about a few minutes, mostly compilation)

For each scene (Miura-ori 4 x 4 and 10 x 10 at fold angle 1.2 rad, the seed's waterbomb with
its stiffnesses), in float64 with ``tol=1e-12``:

* ``forward``: ``jit(solve)(params)`` from the flat sheet (the Newton solve, plus the Hessian
  factorization that :func:`~origami_jax.design.equilibrium_fn` does for its stability check);
* ``gradient``: ``jit(value_and_grad(loss))`` of a random linear loss of the positions with
  respect to every parameter (targets, percent, rest lengths, stiffnesses): the same solve,
  then one Hessian solve with the stored factor and one mixed second derivative;
* the same two warm-started from the equilibrium (the design loop's case: few iterations);
* the gradient's relative error against central differences (step 1e-5) along 3 random
  directions of the targets;
* the design loop: the wall time of a first :func:`~origami_jax.design.design` call (5
  Gauss-Newton steps towards 90 % of the folded height, compilation included) and of a second
  call with another goal of the same kind (95 %), which reuses the compiled steps: all of its
  time is an upper bound on what it spends outside its solves.

Times are medians of ``REPEATS`` runs after compilation. Writes ``design_summary.csv`` and
``design_results.md`` in ``benchmarks/results``.
"""

from __future__ import annotations

import csv
import os
import platform
import statistics
import time
from pathlib import Path

os.environ.setdefault("JAX_ENABLE_X64", "1")

import jax  # noqa: E402
from cores import usable_cores  # noqa: E402 (benchmarks/, the script's folder)

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from origami_jax import patterns  # noqa: E402
from origami_jax.design import design, equilibrium_fn, make_params, target_height  # noqa: E402

REPEATS = 7
TOL = 1e-12
RESULTS = Path(__file__).resolve().parent / "results"


def scenes():
    yield "miura_4x4", patterns.miura_ori(4, 4, fold_angle=1.2), None
    yield "miura_10x10", patterns.miura_ori(10, 10, fold_angle=1.2), None
    yield "seed_waterbomb", patterns.seed_waterbomb(), patterns.SEED_WATERBOMB_STIFFNESS


def median_time(fn, *args) -> float:
    jax.block_until_ready(fn(*args))  # compile (and warm) outside the timing
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def measure(name, cp, stiffness) -> dict:
    params = make_params(cp, stiffness=stiffness)
    solve = equilibrium_fn(cp, tol=TOL)
    rng = np.random.default_rng(0)
    w = jnp.asarray(rng.normal(size=(cp.mesh.num_vertices, 3)))

    def loss(p, start):
        return jnp.vdot(w, solve(p, start)[0])

    forward = jax.jit(lambda p, s: solve(p, s))
    gradient = jax.jit(jax.value_and_grad(loss))
    flat = jnp.asarray(cp.mesh.vertices)
    x, info = forward(params, flat)
    assert bool(info.ok), f"{name}: {info}"
    t_fwd = median_time(forward, params, flat)
    t_grad = median_time(gradient, params, flat)
    t_fwd_warm = median_time(forward, params, x)
    t_grad_warm = median_time(gradient, params, x)
    iterations = int(forward(params, flat)[1].iterations)

    # accuracy: directional derivatives along random target directions
    _, g = gradient(params, x)
    f = jax.jit(lambda t: loss(params._replace(target=t), x))
    errors = []
    h = 1e-5
    for _ in range(3):
        v = jnp.asarray(rng.normal(size=params.target.shape))
        fd = (f(params.target + h * v) - f(params.target - h * v)) / (2 * h)
        errors.append(abs(float(g.target @ v) - float(fd)) / abs(float(fd)))

    # the design loop, twice: the second call compiles nothing
    height = float(jnp.ptp(x[:, 2]))
    loops = []
    for fraction in (0.9, 0.95):
        t0 = time.perf_counter()
        r = design(cp, target_height(fraction * height), params=params, tol=TOL, steps=5)
        loops.append((time.perf_counter() - t0, r.steps))
    return {
        "scene": name,
        "vertices": cp.mesh.num_vertices,
        "dofs": 3 * cp.mesh.num_vertices,
        "iterations": iterations,
        "forward_s": t_fwd,
        "gradient_s": t_grad,
        "ratio": t_grad / t_fwd,
        "forward_warm_s": t_fwd_warm,
        "gradient_warm_s": t_grad_warm,
        "ratio_warm": t_grad_warm / t_fwd_warm,
        "fd_rel_error_max": max(errors),
        "design_steps": loops[1][1],
        "design_first_s": loops[0][0],
        "design_again_s": loops[1][0],
    }


def main() -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)
    rows = []
    for name, cp, stiffness in scenes():
        row = measure(name, cp, stiffness)
        print(
            ", ".join(
                f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()
            )
        )
        rows.append(row)
    with open(RESULTS / "design_summary.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    lines = [
        "# Inverse design: gradient cost and accuracy",
        "",
        f"float64, tol {TOL:g}, median of {REPEATS} runs after compilation; "
        f"{platform.processor() or platform.machine()}, {usable_cores()} cores, "
        f"jax {jax.__version__} on {jax.default_backend()}. "
        "Gradient: `value_and_grad` of a random linear loss of the positions, with respect to "
        "every parameter. Warm: started from the equilibrium. Design: wall time of `design()` "
        "(Gauss-Newton, at most 5 steps, to a height goal), first call (compiling) and a second "
        "call with another goal of the same kind (its steps taken in the column 'steps').",
        "",
        "| scene | vertices | Newton iterations | forward (s) | gradient (s) | ratio | "
        "forward warm (s) | gradient warm (s) | ratio warm | FD rel. error | design first (s) | "
        "design again (s) | steps |",
        "| --- |" + " ---: |" * 12,
    ]
    for r in rows:
        lines.append(
            f"| {r['scene']} | {r['vertices']} | {r['iterations']} | {r['forward_s']:.4f} | "
            f"{r['gradient_s']:.4f} | {r['ratio']:.2f} | {r['forward_warm_s']:.4f} | "
            f"{r['gradient_warm_s']:.4f} | {r['ratio_warm']:.2f} | {r['fd_rel_error_max']:.1e} | "
            f"{r['design_first_s']:.2f} | {r['design_again_s']:.3f} | {r['design_steps']} |"
        )
    (RESULTS / "design_results.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
