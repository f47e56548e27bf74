"""Solves kept on disk as exported programs (origami_jax.exported), and the command's cache."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from origami_jax import exported
from origami_jax.caches import cache_folder, use_compilation_cache


def _fn(tree, n):
    return {"sum": tree["a"].sum() * n, "b": tree["b"] * 2.0}, tree["a"] + 1.0


ARGS = ({"a": jnp.arange(3.0), "b": jnp.ones((2, 2))}, jnp.asarray(3.0))


def test_without_a_folder_it_compiles_as_jit_does(monkeypatch):
    monkeypatch.setattr(exported, "exported_folder", lambda: None)
    compiled = exported.compile_stored(_fn, ARGS, ("fn", 1))
    got, want = compiled(*ARGS), _fn(*ARGS)
    assert jax.tree.all(jax.tree.map(lambda a, b: bool(np.array_equal(a, b)), got, want))
    assert compiled.out_info[1].shape == (3,)


def test_a_stored_program_is_read_back_not_traced_again(tmp_path, monkeypatch):
    monkeypatch.setattr(exported, "exported_folder", lambda: tmp_path)
    first = exported.compile_stored(_fn, ARGS, ("fn", 1))
    files = list(tmp_path.iterdir())
    assert len(files) == 1 and files[0].suffix == ".bin"

    def traced(*args):
        raise AssertionError("traced again")

    again = exported.compile_stored(traced, ARGS, ("fn", 1))  # same key: read from the file
    for out in (first(*ARGS), again(*ARGS)):
        assert float(out[0]["sum"]) == 9.0 and np.array_equal(out[1], [1.0, 2.0, 3.0])
    assert again.out_info[0]["b"].shape == (2, 2)
    # another key, other shapes: a program of its own
    exported.compile_stored(_fn, ARGS, ("fn", 2))
    exported.compile_stored(_fn, ({"a": jnp.arange(4.0), "b": jnp.ones(2)}, 1.0), ("fn", 1))
    assert len(list(tmp_path.iterdir())) == 3


@pytest.mark.parametrize("stored", [False, True])
def test_programs_lowered_first_compile_together(tmp_path, monkeypatch, stored):
    """A program's output shapes before it compiles (the next program's arguments), then both
    compiled at once: the results of each function."""
    monkeypatch.setattr(exported, "exported_folder", lambda: tmp_path if stored else None)
    first = exported.lower_stored(_fn, ARGS, ("fn", 1))
    shapes = first.out_info
    assert shapes[1].shape == (3,) and shapes[0]["b"].shape == (2, 2)

    def second(tree, n):
        return tree["sum"] - n

    then = exported.lower_stored(second, (shapes[0], ARGS[1]), ("second", 1))
    f, g = exported.compile_all([first, then])
    out = f(*ARGS)
    assert float(out[0]["sum"]) == 9.0 and np.array_equal(out[1], [1.0, 2.0, 3.0])
    assert float(g(out[0], ARGS[1])) == 6.0
    assert len(list(tmp_path.iterdir())) == (2 if stored else 0)


def test_a_damaged_file_is_replaced(tmp_path, monkeypatch):
    monkeypatch.setattr(exported, "exported_folder", lambda: tmp_path)
    exported.compile_stored(_fn, ARGS, ("fn", 1))
    (path,) = tmp_path.iterdir()
    path.write_bytes(b"not a program")
    compiled = exported.compile_stored(_fn, ARGS, ("fn", 1))
    assert float(compiled(*ARGS)[0]["sum"]) == 9.0
    assert path.read_bytes() != b"not a program"


def test_host_callbacks_are_compiled_as_usual(tmp_path, monkeypatch):
    monkeypatch.setattr(exported, "exported_folder", lambda: tmp_path)

    def with_callback(x):
        return jax.pure_callback(np.sin, jax.ShapeDtypeStruct(x.shape, x.dtype), x)

    compiled = exported.compile_stored(with_callback, (jnp.ones(2),), "cb", exportable=False)
    assert np.allclose(compiled(jnp.ones(2)), np.sin(1.0))
    assert not list(tmp_path.iterdir())


def test_cache_folder_is_per_user_and_per_machine(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    folder = cache_folder()
    assert folder.parent == tmp_path / "origami_jax" and len(folder.name) == 12
    with pytest.raises(ValueError, match="min_compile_time"):
        use_compilation_cache(tmp_path, min_compile_time=-1.0)


def _command(tmp_path, *extra):
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))
    env.pop("TF_CPP_MIN_LOG_LEVEL", None)
    out = tmp_path / "crease.fold"
    argv = [sys.executable, "-m", "origami_jax", "fold", "--example", "single_crease"]
    run = subprocess.run(
        [*argv, "--out", str(out), "--quiet", *extra],
        env=env,
        capture_output=True,
        text=True,
        cwd=tmp_path,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    return run, out.read_bytes()


def test_the_command_keeps_its_solves_for_the_next_run(tmp_path):
    """The second run reads the first run's programs (no file added or rewritten), writes the
    same result, and XLA's false CPU-feature alarm on loading them is not shown."""
    first, result = _command(tmp_path)
    stored = {p: p.stat().st_mtime_ns for p in (tmp_path / "cache").rglob("exported/*.bin")}
    assert stored
    second, again = _command(tmp_path)
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "cache").rglob("exported/*.bin")} == (
        stored
    )
    assert again == result
    assert "cpu_aot_loader" not in second.stderr


def test_no_cache_writes_nothing(tmp_path):
    _command(tmp_path, "--no-cache")
    assert not (tmp_path / "cache").exists()
