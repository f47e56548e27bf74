"""The documentation site builds in strict mode: a broken link, anchor, snippet, API reference
or docstring cross-reference fails it (``pip install ".[docs]"``; skipped without the tools)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

for module in ("mkdocs", "material", "mkdocstrings_handlers.python", "mkdocs_jupyter"):
    pytest.importorskip(module)


def test_site_builds_strict(tmp_path):
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")  # mkdocs' banner about its successor
    # from the repository root, where mkdocs.yml names its snippets and hooks; a generous
    # limit: the build takes seconds, but CI machines can be loaded
    build = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert build.returncode == 0, build.stdout + build.stderr
    for page in ("index.html", "api/fold/index.html", "notebooks/quickstart/index.html"):
        assert (tmp_path / page).is_file(), page
