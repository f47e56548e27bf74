"""Tests run in float64 (float32 is asked for explicitly where tested)."""

from pathlib import Path

import jax
import pytest

jax.config.update("jax_enable_x64", True)

SHARED = Path(__file__).resolve().parents[2] / "shared"


@pytest.fixture(scope="session")
def shared_patterns() -> Path:
    """../shared/patterns beside the repository; tests using it skip cleanly when absent."""
    path = SHARED / "patterns"
    if not path.is_dir():
        pytest.skip("../shared/patterns is not present")
    return path
