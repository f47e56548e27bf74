"""The suite compiles at XLA's optimisation level 0 (conftest.py), not as users run: here the
stiff and extreme cases (tests/test_stability.py) run again at XLA's defaults."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_stability_at_xla_default_optimisation():
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["ORIGAMI_JAX_TEST_XLA_DEFAULTS"] = "1"  # conftest.py then leaves XLA_FLAGS alone
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:xdist", "-o", "addopts=", "-p",
         "no:cacheprovider", str(ROOT / "tests" / "test_stability.py")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=1800,  # about a minute alone; generous under load
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert " passed" in done.stdout and "failed" not in done.stdout
