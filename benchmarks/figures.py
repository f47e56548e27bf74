"""Render the README's figures into this folder (needs ``pip install ".[viz]"``; about a minute,
most of it compiling; ../shared/patterns is optional):

    python benchmarks/figures.py
"""

import sys
import warnings
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import origami_jax as oj  # noqa: E402
from origami_jax import viz  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
HERE = ROOT / "benchmarks" / "results" / "figures"
SHARED = ROOT.parent / "shared" / "patterns"
DPI = 90


def save(fig, name: str) -> None:
    fig.savefig(HERE / name, dpi=DPI)
    plt.close(fig)
    print("wrote", name)


def main() -> int:
    HERE.mkdir(parents=True, exist_ok=True)
    seed = oj.patterns.seed_waterbomb()
    result = oj.fold(seed, stiffness=oj.patterns.SEED_WATERBOMB_STIFFNESS)
    save(viz.plot_fold(result), "seed_waterbomb.png")
    save(viz.plot_fold(result, color="fold_angle_error"), "seed_waterbomb_error.png")
    save(viz.plot_pattern(seed), "seed_waterbomb_cp.png")

    miura = oj.patterns.miura_ori(6, 6, sector_angle=1.0, fold_angle=1.5)
    save(viz.plot_fold(oj.fold(miura)), "miura_6x6.png")

    history = ROOT / "benchmarks" / "results" / "history.csv"
    if history.exists():
        save(viz.plot_history(history, pattern="miura_30x30"), "history_miura_30x30.png")

    svg = SHARED / "origami-simulator" / "Tessellations" / "waterbomb.svg"
    if svg.exists():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", oj.PatternWarning)
            cp = oj.load(svg)
        # Origami Simulator's default stiffnesses in our units; 70 %: the sheet curls into a tube
        os_stiffness = oj.Stiffness(axial=20.0, facet=0.7, crease=0.7)
        save(viz.plot_fold(oj.fold(cp, percent=0.7, stiffness=os_stiffness)), "os_waterbomb.png")
        save(viz.plot_pattern(cp), "os_waterbomb_cp.png")

    small = oj.patterns.miura_ori(4, 4, sector_angle=1.0, fold_angle=2.0)
    viz.animate_fold(small, HERE / "miura_4x4.gif", frames=20, fps=10, dpi=60, figsize=(5, 4))
    print("wrote miura_4x4.gif")
    return 0


if __name__ == "__main__":
    sys.exit(main())
