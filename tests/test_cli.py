"""The command line: the table, the written file, one-line errors with exit code 2."""

import io
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from origami_jax import io as oio
from origami_jax.cli import main
from origami_jax.fold import SUMMARY_ROWS
from origami_jax.progress import ProgressBar


def test_fold_example_writes_result_and_prints_table(tmp_path, capsys):
    out = tmp_path / "crease.fold"
    code = main(["fold", "--example", "single_crease", "--out", str(out), "--quiet"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    for word in SUMMARY_ROWS:
        assert word in captured.out
    assert out.stat().st_size > 0
    pattern = oio.load(out)
    assert pattern.num_vertices == 6
    folded = __import__("json").loads(out.read_text())["file_frames"][0]
    assert "foldedForm" in folded["frame_classes"]
    assert np.ptp(np.array(folded["vertices_coords"])[:, 2]) > 0.3  # really folded


def test_fold_file_input_and_mesh_output(tmp_path, capsys):
    from origami_jax import patterns

    src = tmp_path / "in.fold"
    oio.save(src, patterns.single_crease(fold_angle=1.0))
    out = tmp_path / "out.obj"
    assert main(["fold", str(src), "--out", str(out), "--percent", "50", "--quiet"]) == 0
    assert out.stat().st_size > 0
    assert "single_crease" in capsys.readouterr().out


def test_fold_path_and_barriers_options(tmp_path, capsys):
    from origami_jax import patterns

    src = tmp_path / "full.fold"
    oio.save(src, patterns.single_crease(fold_angle=np.pi))
    out = tmp_path / "out.fold"
    assert main(["fold", str(src), "--out", str(out), "--quiet"]) == 0
    frames = __import__("json").loads(out.read_text())["file_frames"]
    assert len(frames) > 2  # the path from flat, written frame by frame
    argv = ["fold", str(src), "--out", str(out), "--quiet", "--path", "direct"]
    assert main([*argv, "--barriers", "off"]) == 0
    assert len(__import__("json").loads(out.read_text())["file_frames"]) == 1
    capsys.readouterr()


def test_time_limit_exits_1_with_reason(tmp_path, capsys):
    out = tmp_path / "crease.fold"
    argv = ["fold", "--example", "single_crease", "--out", str(out), "--quiet", "--max-time", "0"]
    assert main(argv) == 1
    assert "time limit reached" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["fold", "missing.fold"], "missing.fold"),
        (["fold", "--example", "single_crease", "--solver", "nope"], "unknown solver"),
        (["fold", "--example", "single_crease", "--out", "x.xyz"], ".xyz"),
        (["render", "--example", "single_crease", "--color", "contact_force"], "--contact fold"),
        (
            ["render", "--example", "single_crease", "--contact", "--color", "contact_force"]
            + ["--out", "x.gif"],
            "colours a picture",
        ),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and message in err and "\n" not in err


def test_malformed_file_from_the_shell(tmp_path):
    bad = tmp_path / "bad.fold"
    bad.write_text('{"vertices_coords": [[0, 0], [1, "x"]]}')
    proc = subprocess.run(
        [sys.executable, "-m", "origami_jax", "fold", str(bad), "--out", str(tmp_path / "o.fold")],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert lines[-1].startswith("error: ") and "vertices_coords[1][1]" in lines[-1]
    assert lines[:-1] == ["warning: file_spec missing; read as FOLD 1.2"]
    assert not (tmp_path / "o.fold").exists()


def test_progress_bar_waits_then_draws():
    stream = io.StringIO()
    bar = ProgressBar(100, delay=10.0, stream=stream)
    bar.update(10)
    assert stream.getvalue() == ""
    bar = ProgressBar(100, delay=0.0, stream=stream)
    bar.update(50, "err 1e-3")
    bar.close()
    text = stream.getvalue()
    assert "50/100" in text and "#" * 12 in text and text.endswith("\n")
    assert np.isfinite(bar.total)


def test_main_leaves_the_process_settings_alone(tmp_path, capsys):
    """``main(argv)`` runs in its caller's process and changes none of its settings (float64,
    warnings' display); the console entry point, which pyproject's script and ``python -m
    origami_jax`` run, makes them."""
    import warnings
    from pathlib import Path

    import jax

    show, x64 = warnings.showwarning, jax.config.jax_enable_x64
    out = tmp_path / "c.fold"
    argv = ["fold", "--example", "single_crease", "--out", str(out), "--quiet", "--float32"]
    assert main(argv) == 0, capsys.readouterr().err
    assert warnings.showwarning is show and jax.config.jax_enable_x64 == x64
    pyproject = (Path(__file__).resolve().parents[1] / "pyproject.toml").read_text()
    assert 'origami-jax = "origami_jax.cli:console_main"' in pyproject


def test_import_changes_no_jax_flag():
    code = "import jax, origami_jax; print(jax.config.jax_enable_x64)"
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=600,
        env={"PATH": "/usr/bin:/bin"},
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "False"


def _shell(*args: str) -> subprocess.CompletedProcess:
    """``python args`` in a fresh interpreter, the package found as this test's is."""
    root = str(Path(__file__).resolve().parents[1])
    env = dict(
        os.environ, PYTHONPATH=os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))
    )
    return subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, timeout=600, env=env
    )


def test_help_and_version_import_no_jax():
    """``--help`` and ``--version`` answer without importing JAX or the package's modules (the
    contract that makes them instant; no wall-clock time is asserted)."""
    import origami_jax

    proc = _shell("-m", "origami_jax", "--help")
    assert proc.returncode == 0, proc.stderr
    assert "fold" in proc.stdout and "render" in proc.stdout and "--version" in proc.stdout
    proc = _shell("-m", "origami_jax", "--version")
    assert proc.returncode == 0 and proc.stdout.split() == ["origami-jax", origami_jax.__version__]
    code = (
        "import sys\n"
        "from origami_jax.cli import build_parser, console_main\n"
        "build_parser()\n"
        "for argv in (['--help'], ['fold', '--help'], ['render', '--help'], ['--version']):\n"
        "    try:\n"
        "        console_main(argv)\n"
        "    except SystemExit as exc:\n"
        "        assert exc.code == 0, (argv, exc.code)\n"
        "heavy = ('jax', 'jaxlib', 'numpy', 'scipy', 'matplotlib')\n"
        "print('imported:', sorted(m for m in sys.modules if m.split('.')[0] in heavy\n"
        "      or m.startswith('origami_jax.') and m != 'origami_jax.cli'))\n"
    )
    proc = _shell("-c", code)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[-1] == "imported: []"


def test_version_attribute():
    import origami_jax

    assert isinstance(origami_jax.__version__, str) and origami_jax.__version__[0].isdigit()
    assert "__version__" in dir(origami_jax) and "fold" in dir(origami_jax)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["fold", "--percent", "250"], "argument --percent: must be from 0 to 100, got 250"),
        (["fold", "--percent", "-5"], "argument --percent: must be from 0 to 100, got -5"),
        (["render", "--percent", "nan"], "argument --percent: must be from 0 to 100, got nan"),
        (["fold", "--percent", "half"], "argument --percent: expected a number, got 'half'"),
        (["fold", "--tol", "0"], "argument --tol: must be a positive number, got 0"),
        (["render", "--tol", "-0.5"], "argument --tol: must be a positive number, got -0.5"),
        (["fold", "--max-time", "-1"], "argument --max-time: must be 0 or more seconds"),
        (["fold", "--max-iter", "-1"], "argument --max-iter: must be 0 or more, got -1"),
        (["render", "--max-iter", "1e3"], "argument --max-iter: expected an integer"),
        (["render", "--frames", "1"], "argument --frames: must be 2 or more, got 1"),
        (["render", "--fps", "0"], "argument --fps: must be 1 or more, got 0"),
        (["render", "--dpi", "0"], "argument --dpi: must be 1 or more, got 0"),
        (["fold", "--contact", "0"], "argument --contact: must be a positive length, got 0"),
        (["fold", "--stiffness", "1,2"], "argument --stiffness: expected AXIAL,FACET,CREASE"),
        (["render", "--stiffness", "0,1,1"], "argument --stiffness: must be positive, got 0"),
        (["fold", "--stiffness", "1,nan,1"], "argument --stiffness: must be 0 or more, got nan"),
    ],
)
def test_out_of_range_arguments_are_refused(argv, message, capsys, tmp_path, monkeypatch):
    """Checked when parsed, before anything is loaded or folded: argparse's usage line and
    ``error: argument ...``, exit code 2."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--example", "single_crease"])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_contact_option_parses_to_fold_s_argument():
    from origami_jax.cli import build_parser

    parse = build_parser().parse_args
    assert parse(["fold"]).contact is False
    assert parse(["fold", "--contact"]).contact is True
    assert parse(["render", "--contact", "0.01"]).contact == 0.01


def test_stiffness_option_folds_with_those_springs(tmp_path, capsys):
    """``--stiffness A,F,C`` and ``origami-simulator`` reach fold(): the seed's scene (not
    rigid-foldable: its equilibrium energy depends on the springs) ends with the energy of a
    fold with those springs, and no line comparing it with the seed paper's."""
    from origami_jax import fold, patterns
    from origami_jax.cli import build_parser
    from origami_jax.energy import ORIGAMI_SIMULATOR_STIFFNESS, Stiffness

    parse = build_parser().parse_args
    assert parse(["fold"]).stiffness is None
    assert parse(["fold", "--stiffness", "2, 0.1,0"]).stiffness == (2.0, 0.1, 0.0)
    out = tmp_path / "crease.fold"
    for given, springs in [
        ("origami-simulator", ORIGAMI_SIMULATOR_STIFFNESS),
        ("2,0.1,0.003", Stiffness(2.0, 0.1, 0.003)),
    ]:
        argv = ["fold", "--example", "seed_waterbomb", "--stiffness", given, "--out", str(out)]
        assert main([*argv, "--quiet"]) == 0
        printed = capsys.readouterr().out
        expected = fold(patterns.seed_waterbomb(), stiffness=springs)
        assert expected.converged and expected.energy > 1e-6
        energy = next(line for line in printed.splitlines() if line.startswith("energy"))
        assert float(energy.split()[-1]) == pytest.approx(expected.energy, rel=1e-5)
        assert "seed paper" not in printed


def test_warmup_compiles_the_smallest_bucket(capsys):
    assert main(["warmup", "--max-vertices", "4", "--quiet"]) == 0
    assert capsys.readouterr().out.strip().startswith("3 solves ready")
    with pytest.raises(SystemExit):
        main(["warmup", "--max-vertices", "3"])
    assert "4 or more" in capsys.readouterr().err
