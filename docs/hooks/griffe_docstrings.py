"""Griffe extension: read the package's docstrings as they are written, for mkdocstrings.

The docstrings are Google style with two habits of Sphinx that griffe does not read:

- ``Example:`` (singular) heads a section of doctests; griffe knows only ``Examples:`` and
  would render the doctests as Markdown text.
- Tables are reStructuredText's simple tables (rows between ``=====  ====`` rules); Markdown
  would read a rule as a heading's underline. Each becomes a Markdown table.
- Cross-references are Sphinx roles (``:func:`fold```, ``:class:`~origami_jax.energy.Reference```).
  Each becomes an optional autoref: a link where the object is documented on the site, plain
  code where it is not (a private helper, say), so a role never breaks the strict build.
"""

from __future__ import annotations

import html
import re

import griffe

EXAMPLE = re.compile(r"^(\s*)Example:[ \t]*$", re.MULTILINE)
RULE = re.compile(r"^( *)=+(?: +=+)+ *$")
ROLE = re.compile(r":(?:func|class|mod|meth|attr|data|exc|obj):`(~?)([\w.]+)(\(\))?`")


def _target(obj: griffe.Object, name: str) -> str:
    """The full path of ``name`` seen from ``obj``'s scope, or ``name`` itself where griffe
    cannot resolve it (autorefs then tries it as written)."""
    scope = obj if isinstance(obj, griffe.Module | griffe.Class) else obj.parent
    head, _, rest = name.partition(".")
    while scope is not None:
        try:
            resolved = scope.resolve(head)
        except griffe.NameResolutionError:
            scope = scope.parent
            continue
        return f"{resolved}.{rest}" if rest else resolved
    return name


def _markdown_tables(text: str) -> str:
    """reStructuredText simple tables as Markdown tables: columns where the rules' ``=`` runs
    are, a line whose first cell is blank continuing the row above; the rows above a middle rule
    are the header (a table without one gets an empty header, which Markdown needs)."""
    lines, out, i = text.split("\n"), [], 0

    def next_rule(start: int) -> int | None:
        """The next rule at or after ``start`` within the same block of non-blank lines."""
        for j in range(start, len(lines)):
            if not lines[j].strip():
                return None
            if RULE.match(lines[j]):
                return j
        return None

    while i < len(lines):
        first = RULE.match(lines[i])
        middle = next_rule(i + 1) if first else None
        if middle is None:
            out.append(lines[i])
            i += 1
            continue
        end = next_rule(middle + 1)
        header, end = (True, end) if end is not None else (False, middle)
        starts = [m.start() for m in re.finditer(r"=+", lines[i])]
        spans = list(zip(starts, [*starts[1:], None], strict=True))
        rows: list[list[str]] = []
        for j in range(i + 1, end):
            if j == middle:
                continue
            cells = [lines[j][a:b].strip() for a, b in spans]
            if rows and j != middle + 1 and not cells[0]:
                joined = zip(rows[-1], cells, strict=True)
                rows[-1] = [f"{old} {new}".strip() for old, new in joined]
            else:
                rows.append(cells)
        if not header:
            rows.insert(0, [""] * len(starts))
        rows.insert(1, ["---"] * len(starts))
        indent = first.group(1)
        # a "|" in a cell is inside code (Markdown's tables leave those alone)
        out.extend(f"{indent}| {' | '.join(row)} |" for row in rows)
        i = end + 1
    return "\n".join(out)


def _rewritten(obj: griffe.Object, text: str) -> str:
    def link(m: re.Match) -> str:
        short, name, call = m.groups()
        shown = (name.rsplit(".", 1)[-1] if short else name) + (call or "")
        identifier = html.escape(_target(obj, name), quote=True)
        return f'<autoref identifier="{identifier}" optional><code>{shown}</code></autoref>'

    return ROLE.sub(link, _markdown_tables(EXAMPLE.sub(r"\1Examples:", text)))


class SphinxHabits(griffe.Extension):
    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:
        seen: set[int] = set()

        def visit(obj: griffe.Object) -> None:
            if id(obj) in seen:
                return
            seen.add(id(obj))
            if obj.docstring is not None:
                obj.docstring.value = _rewritten(obj, obj.docstring.value)
            for member in obj.members.values():
                if not member.is_alias:
                    visit(member)

        visit(pkg)

    # griffe 1's name for the same event
    on_package_loaded = on_package
