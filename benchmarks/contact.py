"""The contact broad phase's build time against the number of triangles (issue 42, step 1).

    python benchmarks/contact.py            # 1,000 to 100,000 triangles (about two minutes)
    python benchmarks/contact.py --quick    # up to 10,000

The scene: a sheet of n x n unit squares (two triangles each), its vertices jittered by a tenth
of a square, folded in half so that its two layers lie a third of ``dhat`` apart (``dhat`` is
:func:`origami_jax.contact.default_dhat` of the flat sheet, the skin as large again): contact
everywhere on the folded half, the broad phase's worst ordinary case. For each size it times

* ``allocate``: the host build that finds the capacities (each new capacity compiles; once);
* ``update``: the jitted build at those capacities, what a solver pays per rebuild (best of 3);
* ``energy+grad``: ``contact_energy`` and its gradient over the candidates (best of 3);

and counts the candidates per triangle (constant when the build is linear). Times are wall
times on this machine's cores (float64); compare sizes within one run. Writes
``contact_summary.csv``, ``contact_results.md`` and (with matplotlib) ``contact_build.png`` in
``benchmarks/results``.
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import time
from pathlib import Path

os.environ.setdefault("JAX_ENABLE_X64", "1")

import jax  # noqa: E402
from cores import cpu_name, usable_cores  # noqa: E402 (benchmarks/, the script's folder)

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from origami_jax import contact  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
SIZES = (1_000, 4_000, 16_000, 50_000, 100_000)
REPEATS = 3


def folded_sheet(triangles: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """Positions, triangles and dhat of the folded sheet with about ``triangles`` triangles."""
    n = max(2, round(np.sqrt(triangles / 2)))
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    x = np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1).astype(float)
    dhat = contact.default_dhat(np.sqrt(2.0) * n)
    x[:, :2] += 0.1 * rng.uniform(-0.5, 0.5, size=(len(x), 2))
    over = x[:, 0] > n / 2
    x[over, 0] = n - x[over, 0]
    x[over, 2] = dhat / 3
    v = ((n + 1) * np.arange(n)[:, None] + np.arange(n)[None, :]).ravel()
    tri = np.concatenate(
        [np.stack([v, v + n + 1, v + n + 2], 1), np.stack([v, v + n + 2, v + 1], 1)]
    )
    return x, tri, dhat


def best_of(fn, repeats: int = REPEATS) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - start)
    return min(times)


def measure(triangles: int) -> dict:
    x, tri, dhat = folded_sheet(triangles)
    mesh = jax.tree.map(jnp.asarray, contact.contact_mesh(tri, len(x)))
    xj = jnp.asarray(x)
    start = time.perf_counter()
    pairs = contact.allocate(xj, mesh, 2 * dhat)
    allocate_s = time.perf_counter() - start
    update = jax.jit(contact.update)
    jax.block_until_ready(update(xj, pairs, mesh))  # compiled here, not timed
    update_s = best_of(lambda: update(xj, pairs, mesh))
    kappa = 1.0
    value_and_grad = jax.jit(jax.value_and_grad(contact.contact_energy))
    jax.block_until_ready(value_and_grad(xj, pairs, dhat, kappa))
    energy_s = best_of(lambda: value_and_grad(xj, pairs, dhat, kappa))
    needed = np.asarray(pairs.needed)
    report = contact.contact_report(xj, pairs, dhat)
    return {
        "triangles": len(tri),
        "vertices": len(x),
        "edges": int(mesh.edges.shape[0]),
        "pt_pairs": int(needed[2]),
        "ee_pairs": int(needed[5]),
        "pairs_per_triangle": round(float(needed[2] + needed[5]) / len(tri), 3),
        "active": int(report.num_active),
        "allocate_s": round(allocate_s, 4),
        "update_s": round(update_s, 5),
        "update_us_per_triangle": round(1e6 * update_s / len(tri), 3),
        "energy_grad_s": round(energy_s, 5),
    }


def write(rows: list[dict]) -> None:
    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / "contact_summary.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    head = "| " + " | ".join(rows[0]) + " |"
    lines = [
        "# Contact broad phase: build time against the number of triangles",
        "",
        f"{cpu_name()}, {usable_cores()} cores, JAX {jax.__version__}, "
        f"Python {platform.python_version()}, float64. `python benchmarks/contact.py`.",
        "",
        "A folded sheet whose two layers lie within dhat over half its area; `update`: the",
        "jitted build at fixed capacities (best of 3), `allocate`: the host build that finds",
        "them (compilations included), `energy_grad`: the contact energy and its gradient.",
        "",
        head,
        "|" + "---|" * len(rows[0]),
        *("| " + " | ".join(str(v) for v in r.values()) + " |" for r in rows),
        "",
    ]
    (RESULTS / "contact_results.md").write_text("\n".join(lines))
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    t = np.array([r["triangles"] for r in rows])
    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.loglog(t, [r["update_s"] for r in rows], "o-", label="update (jitted build)")
    ax.loglog(t, [r["energy_grad_s"] for r in rows], "s-", label="energy + gradient")
    ax.loglog(t, [r["allocate_s"] for r in rows], "^:", label="allocate (with compiles)")
    ref = rows[-1]["update_s"] * t / t[-1]
    ax.loglog(t, ref, "k--", lw=0.8, label="linear")
    ax.set_xlabel("triangles")
    ax.set_ylabel("seconds")
    ax.set_title("contact broad phase")
    ax.legend()
    fig.tight_layout()
    fig.savefig(RESULTS / "contact_build.png", dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="up to 10,000 triangles")
    args = parser.parse_args()
    sizes = [s for s in SIZES if s <= 10_000] if args.quick else SIZES
    rows = []
    for size in sizes:
        rows.append(measure(size))
        print(rows[-1], flush=True)
    write(rows)


if __name__ == "__main__":
    main()
