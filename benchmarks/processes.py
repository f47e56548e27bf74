"""Several processes: fold_batch shared between two processes (jax.distributed on the loopback
address), each on its own core with one JAX CPU device, against one process with one device on
each of the same cores, in one run.

    python benchmarks/processes.py            # about two minutes on 2 cores
    python benchmarks/processes.py --quick    # 256 problems a set, 2 rounds (a smoke run)

Problems: benchmarks/batch.py's sets, 1,024 Miura-ori 4 x 4 and 1,024 waterbomb tessellations
2 x 2 (Newton, float64; one topology each, so shared index arrays). Each setup is a set of
worker processes started once, pinned to its cores (``sched_setaffinity``): it compiles and
folds each set once (the compile time reported), then folds each set again whenever told; the
setups take their rounds in turn (a round of one, then of the other), so that both are timed in
the same spells of this machine, whose speed drifts. A round's time is its slowest process's
wall time of the ``fold_batch`` call (the exchange of results included); the figures are the
medians over the rounds, with their range. Between rounds the two processes also time an
exchange of a payload the size of one's results alone (``all_gather``). The results of the two
setups are compared position by position. Writes ``processes_summary.csv``,
``processes_results.md`` and ``processes_throughput.png`` (with matplotlib) under
benchmarks/results/.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
SETS = ("miura_4x4", "waterbomb_2x2")


def worker(spec: dict) -> None:
    """One process of a setup: compile, then fold a set on each ``go <set>`` line of stdin;
    ``quit`` saves the positions (process 0) and ends."""
    import pickle
    from dataclasses import replace

    import jax

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_num_cpu_devices", spec["devices"])
    if spec["processes"] > 1:
        jax.distributed.initialize(
            coordinator_address=f"127.0.0.1:{spec['port']}",
            num_processes=spec["processes"],
            process_id=spec["process"],
        )
    import numpy as np

    sys.path.insert(0, str(HERE))
    from batch import problem_sets

    from origami_jax import fold_batch
    from origami_jax.processes import all_gather

    sets = problem_sets(spec["problems"])
    results = {}

    def say(**fields) -> None:
        print(json.dumps(fields), flush=True)

    for name in SETS:
        t0 = time.perf_counter()
        found = fold_batch(sets[name], progress=False)
        compile_time = max(r.compile_time for r in found)
        say(set=name, first_call=time.perf_counter() - t0, compile_time=compile_time)
    for line in sys.stdin:
        command, _, name = line.strip().partition(" ")
        if command == "quit":
            break
        t0 = time.perf_counter()
        results[name] = found = fold_batch(sets[name], progress=False)
        seconds = time.perf_counter() - t0
        # an exchange of one process's share of these results alone, as fold_batch sends it
        share = found[jax.process_index() :: jax.process_count()]
        payload = pickle.dumps([replace(r, pattern=None) for r in share], protocol=5)
        t0 = time.perf_counter()
        all_gather(payload)
        say(
            set=name,
            seconds=seconds,
            exchange=time.perf_counter() - t0,
            payload=len(payload),
            converged=sum(r.converged for r in found),
            iterations=float(np.mean([r.iterations for r in found])),
        )
    if spec["process"] == 0:
        positions = {k: np.stack([r.positions for r in rs]) for k, rs in results.items()}
        np.savez(spec["save"], **positions)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Setup:
    """A setup's worker processes, each pinned to its cores."""

    def __init__(self, label: str, cores: list[list[int]], devices: int, n: int, save: Path):
        self.label, self.cores, self.devices = label, cores, devices
        port = _free_port()
        env = dict(os.environ, JAX_PLATFORMS="cpu")
        env.setdefault("OPENBLAS_NUM_THREADS", "1")
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(HERE.parent), env.get("PYTHONPATH")]))
        self.procs = []
        for k, mine in enumerate(cores):
            spec = {
                "devices": devices,
                "processes": len(cores),
                "process": k,
                "port": port,
                "problems": n,
                "save": str(save),
            }
            self.procs.append(
                subprocess.Popen(
                    [sys.executable, __file__, "--worker", json.dumps(spec)],
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    text=True,
                    env=env,
                    preexec_fn=lambda mine=mine: os.sched_setaffinity(0, mine),
                )
            )

    def read(self) -> list[dict]:
        """One line of each process (a JSON object)."""
        lines = [p.stdout.readline() for p in self.procs]
        if not all(lines):
            raise RuntimeError(f"{self.label}: a worker ended early (its output is above)")
        return [json.loads(line) for line in lines]

    def tell(self, line: str) -> None:
        for p in self.procs:
            p.stdin.write(line + "\n")
            p.stdin.flush()

    def close(self) -> None:
        """Tell every process to quit, then wait for all (a process of a jax.distributed run
        waits at exit for the others); kill those that do not end."""
        for p in self.procs:
            try:
                p.stdin.write("quit\n")
                p.stdin.flush()
            except OSError:  # it has ended
                pass
        for p in self.procs:
            try:
                p.wait(timeout=120)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def main(out: Path, quick: bool = False) -> list[dict]:
    sys.path.insert(0, str(HERE))
    from cores import cpu_name

    cores = sorted(os.sched_getaffinity(0))
    if len(cores) < 2:
        raise SystemExit("this comparison needs 2 cores (it runs on the first two)")
    a, b = cores[:2]
    n, rounds = (256, 2) if quick else (1024, 9)
    tmp = out / ".processes"
    tmp.mkdir(parents=True, exist_ok=True)
    setups: list[Setup] = []
    kinds = [
        ("1 process, 2 devices", [[a, b]], 2, tmp / "one.npz"),
        ("2 processes, 1 device each", [[a], [b]], 1, tmp / "two.npz"),
    ]
    try:
        first = {}
        for label, pinned, devices, save in kinds:
            # one setup started and compiled at a time (each on both cores)
            setups.append(setup := Setup(label, pinned, devices, n, save))
            for _ in SETS:
                lines = setup.read()
                first[setup.label, lines[0]["set"]] = lines
                print(setup.label, lines, flush=True)
        timed: dict = {}
        # other processes on this machine slow the setups unevenly (one of two pinned
        # processes, say): the cores they used during the rounds are reported
        pids = [p.pid for setup in setups for p in setup.procs]
        t0, busy0 = time.perf_counter(), _cpu_seconds(pids)
        for k in range(rounds):
            for name in SETS:
                for setup in setups:
                    setup.tell(f"go {name}")
                    lines = setup.read()
                    timed.setdefault((setup.label, name), []).append(lines)
                    print(k, setup.label, name, f"{max(x['seconds'] for x in lines):.3f} s")
        busy1 = _cpu_seconds(pids)
        others = None
        if busy0 and busy1:  # all processes' CPU time less the setups' own, per second
            others = ((busy1[0] - busy0[0]) - (busy1[1] - busy0[1])) / (time.perf_counter() - t0)
    finally:
        for setup in setups:
            setup.close()
    import numpy as np

    one, two = np.load(tmp / "one.npz"), np.load(tmp / "two.npz")
    rows = []
    for name in SETS:
        diff = float(np.max(np.abs(one[name] - two[name])))
        for setup in setups:
            runs = timed[setup.label, name]
            seconds = np.array([max(x["seconds"] for x in lines) for lines in runs])
            exchange = [max(x["exchange"] for x in lines) for lines in runs]
            rates = n / seconds
            compiled = first[setup.label, name]
            rows.append(
                {
                    "set": name,
                    "setup": setup.label,
                    "processes": len(setup.cores),
                    "devices_per_process": setup.devices,
                    "cores": 2,
                    "problems": n,
                    "converged": runs[-1][0]["converged"],
                    "mean_iterations": runs[-1][0]["iterations"],
                    "compile_time_s": max(x["compile_time"] for x in compiled),
                    "first_call_s": max(x["first_call"] for x in compiled),
                    "rounds": rounds,
                    "batch_time_s": float(np.median(seconds)),
                    "folds_per_s": float(np.median(rates)),
                    "folds_per_s_min": float(np.min(rates)),
                    "folds_per_s_max": float(np.max(rates)),
                    "exchange_s": float(np.median(exchange)) if len(setup.cores) > 1 else 0.0,
                    "payload_bytes": max(x["payload"] for x in runs[-1]),
                    "max_position_diff": diff,
                    "other_processes_cores": others,
                }
            )
    write(rows, out, cpu_name())
    for path in tmp.iterdir():
        path.unlink()
    tmp.rmdir()
    return rows


def _cpu_seconds(pids: list[int]) -> tuple[float, float] | None:
    """CPU seconds used so far by all the machine's processes (``/proc/stat``) and by the
    processes ``pids`` (``/proc/PID/stat``); ``None`` where these files are missing."""
    try:
        hz = os.sysconf("SC_CLK_TCK")
        with open("/proc/stat") as f:
            fields = [int(x) for x in f.readline().split()[1:]]
        busy = sum(fields) - fields[3] - fields[4]  # all but idle and iowait
        mine = 0
        for pid in pids:
            with open(f"/proc/{pid}/stat") as f:
                stat = f.read().rsplit(")", 1)[1].split()
            mine += int(stat[11]) + int(stat[12])  # utime, stime
        return busy / hz, mine / hz
    except (OSError, ValueError, IndexError):
        return None


def _others_line(cores: float | str | None) -> str:
    if cores in (None, ""):  # not measured (no /proc)
        return ""
    return (
        f" Other processes on this shared machine used {float(cores):.2f} of its 2 cores on average"
        " during the timed rounds."
    )


def write(rows: list[dict], out: Path, cpu: str) -> None:
    import jax

    with (out / "processes_summary.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    lines = [
        f"Measured {time.strftime('%Y-%m-%d')} on 2 cores ({cpu}), jax {jax.__version__}, CPU;"
        f" Newton, float64, {rows[0]['problems']} problems a set. Each setup on both cores: one"
        " process with a JAX CPU device per core, or two processes (jax.distributed on the"
        " loopback address), each pinned to one core with one device. Medians of"
        f" {rows[0]['rounds']} rounds of one fold_batch call (the setups' rounds in turn),"
        " the range in brackets; a round of two processes lasts until the slower returns (the"
        " exchange of results included). Exchange: an all_gather of one process's results"
        " alone, timed apart. Position diff: largest difference between the two setups'"
        " results." + _others_line(rows[0]["other_processes_cores"]),
        "",
        "| set | setup | converged | mean iterations | compile (s) | batch (s) |"
        " folds/s | exchange (ms) | results sent (kB) | max position diff |",
        "|" + "---|" * 10,
    ]
    for r in rows:
        two = int(r["processes"]) > 1
        lines.append(
            f"| {r['set']} | {r['setup']} | {r['converged']}/{r['problems']} | "
            f"{float(r['mean_iterations']):.1f} | {float(r['compile_time_s']):.1f} | "
            f"{float(r['batch_time_s']):.3f} | {float(r['folds_per_s']):.0f} "
            f"({float(r['folds_per_s_min']):.0f}-{float(r['folds_per_s_max']):.0f}) | "
            + (f"{1e3 * float(r['exchange_s']):.1f} | " if two else "- | ")
            + (f"{float(r['payload_bytes']) / 1e3:.0f}" if two else "-")
            + f" | {float(r['max_position_diff']):.1e} |"
        )
    (out / "processes_results.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    plot(rows, out)


def plot(rows: list[dict], out: Path) -> None:
    """``processes_throughput.png``: folds per second of each setup, per set."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    import numpy as np

    fig, ax = plt.subplots(figsize=(6, 3.2))
    labels = sorted({r["setup"] for r in rows})
    pos = np.arange(len(SETS))
    for k, label in enumerate(labels):
        mine = [next(r for r in rows if r["set"] == s and r["setup"] == label) for s in SETS]
        rate = np.array([float(r["folds_per_s"]) for r in mine])
        low = rate - [float(r["folds_per_s_min"]) for r in mine]
        high = np.array([float(r["folds_per_s_max"]) for r in mine]) - rate
        ax.bar(pos + (k - 0.5) * 0.4, rate, 0.4, yerr=[low, high], capsize=3, label=label)
    ax.set_xticks(pos, SETS)
    ax.set_ylabel("folds per second")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "processes_throughput.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="256 problems a set, 2 rounds")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(json.loads(args.worker))
    else:
        main(HERE / "results", quick=args.quick)
