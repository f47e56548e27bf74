"""origami-jax info: counts, pieces, holes, Kawasaki and Maekawa checks."""

from __future__ import annotations

import numpy as np
import pytest

from origami_jax import CreasePattern
from origami_jax.cli import main
from origami_jax.info import describe


def degree4(centre, letters="MMMV", angle=np.pi) -> CreasePattern:
    """A 2 x 2 square, creases from ``centre`` to the midpoints of the sides."""
    v = [[0, 0], [1, 0], [2, 0], [2, 1], [2, 2], [1, 2], [0, 2], [0, 1], centre]
    border = [[k, (k + 1) % 8] for k in range(8)]
    creases = [[8, 1], [8, 3], [8, 5], [8, 7]]
    faces = [[8, 7, 0, 1], [8, 1, 2, 3], [8, 3, 4, 5], [8, 5, 6, 7]]
    signs = [-1 if a == "M" else 1 for a in letters]
    return CreasePattern(
        v,
        border + creases,
        faces,
        "B" * 8 + letters,
        [0.0] * 8 + [s * angle for s in signs],
    )


def test_flat_foldable_vertex_has_no_warning():
    info = describe(degree4([1, 1]))
    assert (info.vertices, info.edges, info.faces, info.triangles) == (9, 12, 4, 8)
    assert info.assignments == {"B": 8, "M": 3, "V": 1}
    assert (info.pieces, info.holes) == (1, 0)
    assert info.kawasaki == [] and info.maekawa == []


def test_kawasaki_and_maekawa_are_checked():
    info = describe(degree4([0.8, 0.7]))
    assert [v for v, _ in info.kawasaki] == [8]
    assert abs(info.kawasaki[0][1]) > 0.1
    info = describe(degree4([1, 1], letters="MMVV"))
    assert info.maekawa == [(8, 2, 2)]
    assert info.kawasaki == []
    # creases that are not fully folded are not asked to fold flat
    assert describe(degree4([0.8, 0.7], angle=1.0)).kawasaki == []


def test_pieces_holes_and_cli(tmp_path, capsys):
    path = tmp_path / "p.svg"
    path.write_text(
        '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 40">'
        '<rect x="0" y="0" width="30" height="30" stroke="black" fill="none"/>'
        '<rect x="10" y="10" width="10" height="10" stroke="black" fill="none"/>'
        '<rect x="50" y="0" width="30" height="30" stroke="black" fill="none"/>'
        '<line x1="50" y1="0" x2="80" y2="30" stroke="blue"/>'
        '<line x1="90" y1="0" x2="95" y2="5" stroke="red"/>'  # dangling: a warning
        "</svg>"
    )
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "pieces                2" in out
    assert "holes                 1" in out
    assert "warning: <line> 4" in out and "dropped" in out


def test_cli_info_bad_file(tmp_path, capsys):
    path = tmp_path / "bad.svg"
    path.write_text("<svg")
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("error: ") and "bad.svg" in err[-1]


@pytest.mark.parametrize("letters", ["MMMV", "VVVM"])
def test_summary_names_the_vertex(letters):
    text = describe(degree4([0.8, 0.7], letters=letters)).summary()
    assert "vertex 8: breaks Kawasaki's condition" in text
