"""Time to first fold: fresh processes fold each shared file, phase by phase, cold and warm cache.

    python benchmarks/latency.py                  # every file, cold and warm cache
    python benchmarks/latency.py --quick          # the 4 Origami Simulator Bases only
    python benchmarks/latency.py --passes cold,warm,command   # also the real command's time
    python benchmarks/latency.py --files 'origami-simulator/doc/*.svg'

Each file of ../shared/patterns (``--patterns``) is folded in a fresh Python process that
imports JAX and origami_jax, turns on float64 and the persistent compilation cache
(:func:`origami_jax.use_compilation_cache`), loads the file, folds it with the defaults (no
:func:`origami_jax.tune_process`, which the command calls) and saves the result to a .fold file;
it prints its phase times as one JSON line. The parent times the whole process from outside
(start to exit). Passes: ``cold``, a new empty cache folder (``XDG_CACHE_HOME`` set to a fresh
temporary folder); ``warm``, the same folder once the cold pass has folded every file;
``command``, ``python -m origami_jax fold FILE --out X.fold --quiet`` on the warm cache, its
total time only (what a user waits for). Warm and command need the cold pass's folder: the cold
pass runs whenever they are asked for. ``warmed``: a new cache folder filled by
``origami-jax warmup`` alone (its time is reported), then each file as in the warm pass: the
first fold of a pattern never folded before, on an installation that ran the warmup.

Writes ``latency_<pass>.csv``, ``latency_results.md`` and ``latency.png`` (matplotlib) to
``benchmarks/results/`` (``--out``). Standard library only in this process: it imports
neither JAX nor the package, so it changes nothing its children inherit but the variables set.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from importlib.metadata import version
from pathlib import Path

from cores import cpu_name, usable_cores  # benchmarks/, the script's folder

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(__file__).resolve().parents[2] / "shared" / "patterns"  # as benchmarks/run.py
QUICK = "origami-simulator/Bases/*.svg"
PASSES = ("cold", "warm", "command", "warmed")
FAILED = ("timeout", "no output")  # and "exit N": a process that did not fold
XMAX = 30.0  # seconds: the plot's axis ends here (a longer bar is cut, its total written)
# the child's phases in order; "fold other": fold() outside compile and solve (mesh, energy,
# start state), "exit": printing the line and the interpreter's shutdown (total minus the rest)
PHASES = ("import", "load", "compile", "solve", "fold_other", "write", "exit")

# one fold in a fresh process; argv: the file, the output .fold, the parent's time.time() at
# launch. "import" counts the interpreter's start and the lazy names' modules (fold, io).
CHILD = """
import json, sys, time
path, out, launched = sys.argv[1], sys.argv[2], float(sys.argv[3])
import jax
import origami_jax
from origami_jax import fold, load, save, use_compilation_cache
jax.config.update("jax_enable_x64", True)
use_compilation_cache()
t1 = time.time()
pattern = load(path)
t2 = time.time()
result = fold(pattern)
t3 = time.time()
save(out, result)
t4 = time.time()
print(json.dumps({
    "vertices": pattern.num_vertices,
    "import_s": t1 - launched,
    "load_s": t2 - t1,
    "compile_s": result.compile_time,
    "solve_s": result.wall_time,
    "fold_other_s": t3 - t2 - result.compile_time - result.wall_time,
    "write_s": t4 - t3,
    "done_s": t4 - launched,
    "iterations": result.iterations,
    "status": result.status.name.lower(),
}))
"""


def run(cmd: list[str], env: dict, timeout: float) -> tuple[float, str, str]:
    """Run ``cmd`` once: its wall time from start to exit, its status (``ok``, ``exit N`` or
    ``timeout``) and its stdout."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(
            cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired:
        return time.perf_counter() - t0, "timeout", ""
    total = time.perf_counter() - t0
    if proc.returncode:
        print(proc.stderr[-2000:], file=sys.stderr)
    return total, "ok" if proc.returncode == 0 else f"exit {proc.returncode}", proc.stdout


def fold_row(name: str, path: Path, env: dict, work: Path, timeout: float) -> dict:
    """Fold ``path`` in a fresh process: one CSV row (phases NaN where the child failed)."""
    launched = time.time()  # passed to the child, which counts its import phase from it
    cmd = [sys.executable, "-c", CHILD, str(path), str(work / "out.fold"), repr(launched)]
    total, status, stdout = run(cmd, env, timeout)
    lines = [ln for ln in stdout.splitlines() if ln.startswith("{")]
    child = json.loads(lines[-1]) if status == "ok" and lines else {}
    if child:
        child["exit_s"] = total - child["done_s"]
    row = {"file": name, "vertices": child.get("vertices", "")}
    row.update({f"{p}_s": child.get(f"{p}_s", float("nan")) for p in PHASES})
    row.update(total_s=total, iterations=child.get("iterations", ""))
    row["status"] = child.get("status", "no output" if status == "ok" else status)
    return row


def command_row(name: str, path: Path, env: dict, work: Path, timeout: float) -> dict:
    """The real command on ``path``: its total wall time only."""
    cmd = [sys.executable, "-m", "origami_jax", "fold", str(path)]
    total, status, _ = run([*cmd, "--out", str(work / "out.fold"), "--quiet"], env, timeout)
    status = {"ok": "converged", "exit 1": "not converged"}.get(status, status)
    return {"file": name, "total_s": total, "status": status}


def write_csv(path: Path, rows: list[dict]) -> None:
    # as benchmarks/run.py's, which this script does not import: run.py imports JAX and tunes
    # its process (environment variables that the children would inherit)
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def folder_mib(folder: Path) -> float:
    return sum(f.stat().st_size for f in folder.rglob("*") if f.is_file()) / 2**20


def machine() -> str:
    return (
        f"{platform.machine()}, {usable_cores()} cores ({cpu_name()}), Python "
        f"{platform.python_version()}, jax {version('jax')}, jaxlib {version('jaxlib')}"
    )


def summary_line(name: str, rows: list[dict]) -> str:
    totals = [r["total_s"] for r in rows]
    # only the processes that folded count as within a limit (not a timeout or a failure)
    done = [r["total_s"] for r in rows if r["status"] not in FAILED and "exit" not in r["status"]]
    within = [sum(t <= limit for t in done) for limit in (2.0, 5.0)]
    return (
        f"| {name} | {len(rows)} | {statistics.median(totals):.2f} | {max(totals):.2f} | "
        f"{within[0]} | {within[1]} |"
    )


def cell(value: object) -> str:
    if isinstance(value, float):
        return "-" if value != value else f"{value:.2f}"  # NaN: the process gave no times
    return str(value)


def markdown(results: dict[str, list[dict]], cache_mib: float, timeout: float) -> str:
    lines = [
        f"Measured {time.strftime('%Y-%m-%d')} on {machine()}; one fresh process per file "
        "and pass, timed from outside (process start to exit: 'total'). The child imports JAX "
        "and origami_jax (with the interpreter's start: 'import'), turns on float64 and "
        "`use_compilation_cache()`, loads the file ('load'), folds it with the defaults "
        "(`result.compile_time`: 'compile', `result.wall_time`: 'solve', the rest of `fold()`: "
        "'fold other') and saves the result to a .fold file ('write'); 'exit': the interpreter's "
        "shutdown. Cold: a new empty cache folder (`XDG_CACHE_HOME`), filled file by file as the "
        "pass goes (a later file may find programs that an earlier one stored); warm: the same "
        f"folder after the cold pass ({cache_mib:.0f} MiB). Timeout {timeout:g} s per process. "
        "The machine is shared with other work: times are noisy, by a second or more.",
        "",
        "## Summary",
        "",
        "| pass | files | median total (s) | max total (s) | at most 2 s | at most 5 s |",
        "|---|---|---|---|---|---|",
    ]
    lines += [summary_line(name, rows) for name, rows in results.items()]
    lines += [
        "",
        "'load': the machine's load average over the last minute as the process started, on "
        f"{usable_cores()} cores; the benchmark's own processes make about 1 to 2 of it, more "
        "means that other work competed for the cores.",
    ]
    titles = {
        "cold": "Cold cache",
        "warm": "Warm cache",
        "command": "The command (`python -m origami_jax fold FILE --out X.fold --quiet`), warm",
        "warmed": "After `origami-jax warmup` only: patterns never folded before",
    }
    for name, rows in results.items():
        lines += ["", f"## {titles[name]}", ""]
        if name == "command":
            head, keys = ["file", "total (s)", "status"], ["file", "total_s", "status"]
        else:
            head = ["file", "vertices", *(p.replace("_", " ") + " (s)" for p in PHASES)]
            head += ["total (s)", "iterations", "status"]
            keys = ["file", "vertices", *(f"{p}_s" for p in PHASES), "total_s"]
            keys += ["iterations", "status"]
        head, keys = [*head, "load"], [*keys, "load_1min"]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for r in rows:
            lines.append("| " + " | ".join(cell(r[k]) for k in keys) + " |")
    return "\n".join(lines) + "\n"


def plot(results: dict[str, list[dict]], out: Path) -> None:
    """Per file, the cold and the warm process's phases as stacked bars (the command's total
    as a mark), each total written; bars longer than :data:`XMAX` are cut there."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bars = [(name, results[name]) for name in ("cold", "warm") if name in results]
    files = [r["file"] for r in bars[0][1]]
    xmax = min(max(r["total_s"] for _, rows in bars for r in rows), XMAX)
    height = 0.8 / len(bars)
    fig, ax = plt.subplots(figsize=(11, 0.45 * len(files) + 2))
    colors = plt.get_cmap("tab10").colors
    for b, (name, rows) in enumerate(bars):
        y = [i + (b - (len(bars) - 1) / 2) * height for i in range(len(rows))]
        left = [0.0] * len(rows)
        for p, phase in enumerate(PHASES):
            width = [r[f"{phase}_s"] if r[f"{phase}_s"] == r[f"{phase}_s"] else 0 for r in rows]
            label = phase.replace("_", " ") if b == 0 else None
            hatch = "//" if name == "warm" else None
            ax.barh(y, width, height, left, color=colors[p], hatch=hatch, label=label, lw=0)
            left = [a + w for a, w in zip(left, width, strict=True)]
        for yi, r in zip(y, rows, strict=True):
            x = min(r["total_s"], xmax)
            box = {"fc": "white", "ec": "none", "pad": 0.5}  # legible over a cut bar
            ax.text(x, yi, f" {name} {r['total_s']:.1f}", va="center", fontsize=6, bbox=box)
    if "command" in results:
        y = [i + (len(bars) - 1) / 2 * height for i in range(len(files))]
        x = [min(r["total_s"], xmax) for r in results["command"]]
        ax.plot(x, y, "k|", ms=8, label="command total (warm)")
    ax.set_yticks(range(len(files)), [f.split("/")[-1] for f in files], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlim(0, xmax * 1.12)
    ax.set_xlabel(
        f"seconds, fresh process (plain bars: cold cache, hatched: warm; cut at {XMAX:g} s)"
    )
    ax.set_title("Time to first fold, by phase")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--patterns", type=Path, default=SHARED, help="the patterns folder")
    parser.add_argument("--files", default=None, help="a glob under it (default: every file)")
    parser.add_argument("--quick", action="store_true", help=f"only {QUICK}")
    parser.add_argument("--passes", default="cold,warm", help="of cold,warm,command,warmed")
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds per process")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args(argv)
    passes = args.passes.split(",")
    if not set(passes) <= set(PASSES):
        parser.error(f"--passes: of {','.join(PASSES)}, got {args.passes}")
    glob = QUICK if args.quick else args.files
    paths = sorted(args.patterns.glob(glob) if glob else args.patterns.rglob("*"))
    paths = [p for p in paths if p.suffix.lower() in (".svg", ".fold") and p.is_file()]
    if not paths:
        parser.error(f"no .svg or .fold file under {args.patterns} ({glob or 'all'})")
    args.out.mkdir(parents=True, exist_ok=True)
    results: dict[str, list[dict]] = {}
    with tempfile.TemporaryDirectory(prefix="origami-latency-") as tmp:
        work = Path(tmp)
        python_path = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
        env = dict(os.environ, XDG_CACHE_HOME=str(work / "cache"), PYTHONPATH=python_path)
        env["TF_CPP_MIN_LOG_LEVEL"] = "3"  # as the command: no XLA log line per cached program
        cache_mib = 0.0
        for name in PASSES:
            if name != "cold" and name not in passes:
                continue  # the cold pass always runs: it fills the cache that the others need
            one = command_row if name == "command" else fold_row
            here = env
            if name == "warmed":  # a cache of its own, filled by the warmup only
                here = dict(env, XDG_CACHE_HOME=str(work / "warmed"))
                cmd = [sys.executable, "-m", "origami_jax", "warmup", "--quiet"]
                seconds, _, _ = run(cmd, here, args.timeout * 10)
                warmup_s = seconds
                print(f"warmup {seconds:.1f} s", flush=True)
            rows = []
            for path in paths:
                load = os.getloadavg()[0]  # the machine's busyness as the process starts
                r = one(str(path.relative_to(args.patterns)), path, here, work, args.timeout)
                r["load_1min"] = load
                rows.append(r)
                print(f"{name:8s} {r['file']:55s} {r['total_s']:7.2f} s  {r['status']}", flush=True)
            if name == "cold":
                cache_mib = folder_mib(work / "cache")
            if name in passes:
                results[name] = rows
                write_csv(args.out / f"latency_{name}.csv", rows)
    text = markdown(results, cache_mib, args.timeout)
    if "warmed" in results:
        text += f"\n`origami-jax warmup` (the warmed pass's cache) took {warmup_s:.1f} s.\n"
    (args.out / "latency_results.md").write_text(text)
    print(text)
    if "cold" in results or "warm" in results:
        try:
            plot(results, args.out / "latency.png")
        except ImportError:
            print("matplotlib not installed: no plot (pip install '.[bench]')", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
