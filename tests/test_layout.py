"""The package's modules share public names only (issue 43: no private reach-ins)."""

import ast
from pathlib import Path

import origami_jax

# a named tuple's own API, public despite the underscore
NAMEDTUPLE = {"_fields", "_replace", "_asdict", "_make", "_field_defaults"}


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__") and name not in NAMEDTUPLE


def private_uses(root: Path) -> list[str]:
    """Every ``from origami_jax.a import _x`` (or a relative one) and every ``a._x`` where
    ``a`` is an imported module or name, in the ``.py`` files under ``root`` (imports inside
    functions included)."""
    found = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        imported = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                ours = node.level > 0 or (node.module or "").startswith("origami_jax")
                for alias in node.names:
                    if ours and _private(alias.name):
                        found.append(f"{path.name}:{node.lineno} imports {alias.name}")
                    imported.add(alias.asname or alias.name)
            elif isinstance(node, ast.Import):
                imported |= {(a.asname or a.name).split(".")[0] for a in node.names}
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and node.value.id in imported
                and _private(node.attr)
            ):
                found.append(f"{path.name}:{node.lineno} uses {node.value.id}.{node.attr}")
    return found


def test_no_module_uses_another_modules_private_names():
    assert private_uses(Path(origami_jax.__file__).parent) == []


def test_the_check_finds_a_private_reach_in(tmp_path):
    (tmp_path / "a.py").write_text(
        "import numpy\nfrom origami_jax.fold import _x, y\n\n\ndef f():\n    return numpy._y\n"
    )
    assert private_uses(tmp_path) == ["a.py:2 imports _x", "a.py:6 uses numpy._y"]
