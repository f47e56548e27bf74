"""Batch folding: folds per second of fold_batch against a Python loop of fold(), and the
compile count of a stream of patterns of random sizes.

    python benchmarks/run.py --part batch     # (or: python benchmarks/batch.py)
    python benchmarks/batch.py --stream       # only the stream, into an earlier run's files

Problems: 1,024 Miura-ori 4 x 4 with random sector angles (50 to 80 degrees) and fold angles
(0.3 to 2.5 rad), and 1,024 waterbomb tessellations 2 x 2 with random fold angles (0.3 to 2.5
rad), all triangulated beforehand (in neither timing); each set is of one topology, so
fold_batch vmaps it unpadded with shared index arrays (its default). The process makes two JAX
CPU devices per core (``jax_num_cpu_devices``, see ``cores.DEVICES_PER_CORE``), which
fold_batch uses by default; Newton folds each set three times more: on one device per core, on
one device, and padded to its size bucket (``share_topology=False``, as a set of mixed patterns
would be). Each solver folds the whole set with one ``fold_batch`` call
(after a first call on 256 of them that compiles it; compile time reported apart) and 64 of
them (4 with --quick; other ones for each row and repetition: none folded alone before) one by
one with ``fold`` (compiled beforehand); the ratio is folds per second of the batch over those
of the loop, measured in the same run. The Newton rows repeat the pair (batch, then loop) three
times and report the medians, with the range of the rate and of the ratio (see
:func:`throughput`). The stream: 100
patterns of random kinds and sizes, each folded by its own ``fold_batch`` call, as they would
arrive one at a time; we count the compilations. Writes ``batch_summary.csv``,
``batch_results.md`` and ``batch_throughput.png``.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("JAX_ENABLE_X64", "1")

import jax  # noqa: E402
from cores import cpu_devices, cpu_name, usable_cores  # noqa: E402 (benchmarks/)

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from origami_jax import fold, fold_batch, patterns  # noqa: E402
from origami_jax.batch import bucket, compile_count, problem_sizes  # noqa: E402

SOLVERS = ("newton", "lbfgs", "dynamics")


def problem_sets(n: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    miura = [
        patterns.miura_ori(
            4,
            4,
            sector_angle=np.radians(rng.uniform(50, 80)),
            fold_angle=rng.uniform(0.3, 2.5),
        )
        for _ in range(n)
    ]
    bombs = [patterns.waterbomb(2, 2, fold_angle=rng.uniform(0.3, 2.5)) for _ in range(n)]
    for cp in miura + bombs:
        _ = cp.mesh  # a pattern triangulates on first use: here, before either timing
    return {"miura_4x4": miura, "waterbomb_2x2": bombs}


def stream(n: int, seed: int = 1) -> list:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        if rng.random() < 0.5:
            nx, ny = rng.integers(2, 9, size=2)
            out.append(patterns.miura_ori(int(nx), int(ny), fold_angle=rng.uniform(0.3, 2.5)))
        else:
            nn, mm = rng.integers(1, 4, size=2)
            out.append(patterns.waterbomb(int(nn), int(mm), fold_angle=rng.uniform(0.3, 2.5)))
    return out


def throughput(runs: list[tuple], cps: list) -> list[dict]:
    """One row per run ``(solver, share_topology, devices, loop_samples)`` over the set ``cps``.

    ``share_topology``: as in fold_batch (None: the default, shared index arrays for a set of one
    topology; False: padded to the size buckets); ``devices``: fold_batch's (None: all, two per
    core). One repetition per loop sample: the whole set with one fold_batch call, then the
    sample one by one with fold(). The runs take their repetitions in turn (the first of each,
    then the second of each...), so that rows compare in the same spells of this machine, whose
    speed drifts by up to 2x within minutes; the figures are the medians over a run's
    repetitions (each ratio pairs timings taken seconds apart), with the range of the batch's
    rate and of the ratio."""
    rows = []
    for solver, share_topology, devices, _ in runs:
        kw = {
            "solver": solver,
            "progress": False,
            "share_topology": share_topology,
            "devices": devices,
        }
        t0 = time.perf_counter()
        # compiles the slots' shape (the same for any set of 256 or more: slots and queue)
        warm = fold_batch(cps[:256], **kw)
        rows.append(
            {
                "kw": kw,
                "first_call": time.perf_counter() - t0,
                "compile_time": max(r.compile_time for r in warm),
                "batch": [],
                "loop": [],
                "diff": 0.0,
            }
        )
    for solver in {run[0] for run in runs}:
        fold(cps[-1], solver=solver)  # compile the single solve (on a pattern no loop folds)
    for k in range(max(len(run[3]) for run in runs)):
        for (solver, _, _, samples), row in zip(runs, rows, strict=True):
            if k >= len(samples):
                continue
            t0 = time.perf_counter()
            results = fold_batch(cps, **row["kw"])
            row["batch"].append(time.perf_counter() - t0)
            sample = cps[samples[k]]
            t0 = time.perf_counter()
            singles = [fold(cp, solver=solver) for cp in sample]
            row["loop"].append((time.perf_counter() - t0) / len(sample))
            row["results"] = results
            row["diff"] = max(
                row["diff"],
                *(
                    float(np.max(np.abs(r.positions - s.positions)) / cp.diameter)
                    for r, s, cp in zip(results[samples[k]], singles, sample, strict=True)
                ),
            )
    sizes = problem_sizes(cps[0])
    topologies = len({(cp.mesh.triangles.tobytes(), cp.mesh.edges.tobytes()) for cp in cps})
    out = []
    for (solver, share_topology, devices, samples), row in zip(runs, rows, strict=True):
        results = row["results"]
        batch_rates = len(cps) / np.array(row["batch"])
        ratios = np.array(row["loop"]) * len(cps) / np.array(row["batch"])
        shared = share_topology is not False and topologies == 1
        out.append(
            {
                "solver": solver,
                "problems": len(cps),
                "layout": "shared topology" if shared else "size buckets",
                "devices": len(devices or jax.devices()),
                "solved_vertices": sizes.vertices if shared else bucket(sizes).vertices,
                "converged": sum(r.converged for r in results),
                "mean_iterations": float(np.mean([r.iterations for r in results])),
                "compile_time_s": row["compile_time"],
                "first_call_s": row["first_call"],
                "repetitions": len(samples),
                "loop_problems": len(cps[samples[0]]),
                "batch_time_s": float(np.median(row["batch"])),
                "batch_folds_per_s": float(np.median(batch_rates)),
                "batch_folds_per_s_min": float(np.min(batch_rates)),
                "batch_folds_per_s_max": float(np.max(batch_rates)),
                "loop_folds_per_s": float(np.median(1.0 / np.array(row["loop"]))),
                "speedup": float(np.median(ratios)),
                "speedup_min": float(np.min(ratios)),
                "speedup_max": float(np.max(ratios)),
                "max_position_diff_vs_single": row["diff"],
                "max_fold_angle_error": max(r.fold_angle_error_max for r in results),
            }
        )
    return out


# repetitions of each Newton row (the others take seconds to minutes per batch: one)
NEWTON_REPETITIONS = 3


def main(out: Path, quick: bool = False) -> list[dict]:
    n = 64 if quick else 1024
    rows = []
    for name, cps in problem_sets(n).items():
        # Newton with the defaults (one topology: shared index arrays; all devices), on one
        # device per core, on one device, and padded to its size bucket, its repetitions taken
        # in turn; then the other solvers with the defaults
        configs = [("newton", None, None)]
        if 1 < usable_cores() < len(jax.devices()):
            configs.append(("newton", None, jax.devices()[: usable_cores()]))
        configs += [("newton", None, jax.devices()[:1]), ("newton", False, None)]
        configs += [(s, None, None) for s in SOLVERS if s != "newton"]
        reps = [NEWTON_REPETITIONS if solver == "newton" else 1 for solver, _, _ in configs]
        # each repetition's loop folds patterns no single fold has seen (a pattern's first
        # fold builds what later ones reuse, such as Newton's assembly layout)
        m = min(64, n // sum(reps))
        starts = np.cumsum([0] + reps) * m
        runs = [
            (*config, [slice(a, a + m) for a in range(starts[k], starts[k + 1], m)])
            for k, config in enumerate(configs)
        ]
        newton = [run for run in runs if run[0] == "newton"]
        others = [run for run in runs if run[0] != "newton"]
        measured = throughput(newton, cps) + [throughput([run], cps)[0] for run in others]
        for run, row in zip(newton + others, measured, strict=True):
            row = {"set": name, **row}
            rows.append(row)
            print(
                f"{name:14s} {run[0]:9s} {row['devices']} dev {row['layout']:15s} batch "
                f"{row['batch_folds_per_s']:8.1f} folds/s  loop "
                f"{row['loop_folds_per_s']:7.1f} folds/s  x{row['speedup']:.1f}  "
                f"{row['converged']}/{n} converged  compile {row['compile_time_s']:.1f} s",
                flush=True,
            )
    rows.append(stream_row(20 if quick else 100))
    write(rows, out)
    return rows


def stream_row(n: int) -> dict:
    """Fold a stream of ``n`` patterns, each by its own fold_batch call; count compilations."""
    before = compile_count()
    patterns_stream = stream(n)
    t0 = time.perf_counter()
    for cp in patterns_stream:
        fold_batch(cp, progress=False)
    stream_time = time.perf_counter() - t0
    compiles = compile_count() - before
    buckets = len({bucket(problem_sizes(cp)) for cp in patterns_stream})
    vertex_counts = [cp.mesh.num_vertices for cp in patterns_stream]
    print(f"stream: {compiles} compilations, {buckets} buckets, {stream_time:.1f} s")
    return {
        "set": f"stream of {len(patterns_stream)} ({min(vertex_counts)} to "
        f"{max(vertex_counts)} vertices)",
        "solver": "newton",
        "problems": len(patterns_stream),
        "compiles": compiles,
        "buckets": buckets,
        "batch_time_s": stream_time,
    }


def stream_line(r: dict) -> str:
    return (
        f"{r['set']}, each folded by its own fold_batch call (Newton): {r['compiles']} "
        f"compilations for {r['buckets']} size buckets, {float(r['batch_time_s']):.1f} s in all."
    )


def update_stream(out: Path) -> None:
    """Rerun only the stream and replace its row in the files of an earlier full run."""
    import csv

    r = stream_row(100)
    with (out / "batch_summary.csv").open(newline="") as fh:
        reader = csv.DictReader(fh)
        fields, rows = reader.fieldnames, list(reader)
    rows = [dict(row, **r) if row["set"].startswith("stream of") else row for row in rows]
    with (out / "batch_summary.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    md = out / "batch_results.md"
    lines = [stream_line(r) if x.startswith("stream of") else x for x in md.read_text().split("\n")]
    md.write_text("\n".join(lines))


def _ranged(r: dict, key: str, spec: str) -> str:
    """``r[key]``, with its range over the repetitions when there were several."""
    text = format(float(r[key]), spec)
    if int(r.get("repetitions", 1)) > 1:
        text += f" ({float(r[key + '_min']):{spec}}-{float(r[key + '_max']):{spec}})"
    return text


def write(rows: list[dict], out: Path) -> None:
    import csv

    out.mkdir(parents=True, exist_ok=True)
    fields = sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k)
                    if k in rows[0] else 100)  # fmt: skip
    with (out / "batch_summary.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    device = jax.devices()[0]
    lines = [
        f"Measured {time.strftime('%Y-%m-%d')} on {usable_cores()} cores ({cpu_name()}), jax"
        f" {jax.__version__}, {device.platform}: {device.device_kind}; float64. Batch: one"
        " fold_batch call (compile excluded); loop: fold() one by one on"
        f" {rows[0]['loop_problems']} of them, other ones"
        " for each row and repetition (compiled beforehand). Newton rows: medians of"
        f" {NEWTON_REPETITIONS} repetitions (batch, then loop; a set's Newton rows take theirs"
        " in turn), the range in brackets.",
        "",
        "| set | solver | problems | layout | devices | vertices solved | converged |"
        " mean iterations | compile (s) | batch (s) | batch folds/s | loop folds/s |"
        " batch / loop | max position diff vs single (of diameter) |",
        "|" + "---|" * 14,
    ]
    for r in rows:
        if "compiles" in r:
            continue
        lines.append(
            f"| {r['set']} | {r['solver']} | {r['problems']} | {r['layout']} | "
            f"{r['devices']} | {r['solved_vertices']} | "
            f"{r['converged']} | {r['mean_iterations']:.0f} | {r['compile_time_s']:.1f} | "
            f"{r['batch_time_s']:.2f} | {_ranged(r, 'batch_folds_per_s', '.0f')} | "
            f"{r['loop_folds_per_s']:.0f} | {_ranged(r, 'speedup', '.1f')} | "
            f"{r['max_position_diff_vs_single']:.1e} |"
        )
    for r in rows:
        if "compiles" in r:
            lines += [
                "",
                stream_line(r),
            ]
    (out / "batch_results.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    plot([r for r in rows if "compiles" not in r], out)


def plot(data: list[dict], out: Path) -> None:
    """``batch_throughput.png``: folds per second of the batch and of the loop, per row."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, ax = plt.subplots(figsize=(9, 4))
    labels = [
        r["set"].replace("_", "\n", 1)
        + f"\n{r['solver']}"
        + ("\n(buckets)" if r["layout"] == "size buckets" else "")
        + (
            f"\n({r['devices']} device{'s' * (int(r['devices']) > 1)})"
            if int(r["devices"]) < len(jax.devices())
            else ""
        )
        for r in data
    ]
    pos = np.arange(len(data))
    ax.bar(pos - 0.2, [float(r["batch_folds_per_s"]) for r in data], 0.4, label="fold_batch")
    ax.bar(pos + 0.2, [float(r["loop_folds_per_s"]) for r in data], 0.4, label="loop of fold()")
    ax.set_xticks(pos, labels, fontsize=7)
    ax.set_yscale("log")
    ax.set_ylabel("folds per second")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "batch_throughput.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    # two JAX devices per core (cores.DEVICES_PER_CORE): fold_batch splits its slots across
    # them and they run side by side. Set here, not on import, so that a script importing
    # problem_sets keeps its own device count (run.py sets its own).
    jax.config.update("jax_num_cpu_devices", cpu_devices())
    if "--stream" in sys.argv:  # only the stream, into the files of an earlier full run
        update_stream(Path(__file__).parent / "results")
    else:
        main(Path(__file__).parent / "results", quick="--quick" in sys.argv)
