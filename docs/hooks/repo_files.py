"""MkDocs hook: the site serves the notebooks and the benchmarks' pictures from where they lie.

They live outside ``docs/`` (``notebooks/``, ``benchmarks/results/``), and the pages link to them
by their place in the repository (``../notebooks/quickstart.ipynb``), so that the Markdown also
reads right as plain files (on GitHub, say). The site serves them under its root at the same
paths (``notebooks/quickstart.ipynb``, rendered by mkdocs-jupyter), and this hook rewrites those
links to match; every other link is left to MkDocs, whose strict mode checks it.
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[2]
# folder (relative to the repository) -> the files of it that the site serves
SERVED = {
    "notebooks": ("*.ipynb",),
    "benchmarks/results": ("*.png", "*.gif", "figures/*.png", "figures/*.gif"),
}
# the target of a Markdown link or image: ](target) or ](target "title")
LINK = re.compile(r"(\]\()([^)\s]+)")


# before mkdocs-jupyter's on_files (priority 0), which converts the notebooks it finds
@event_priority(100)
def on_files(files: Files, config) -> Files:
    for folder, patterns in SERVED.items():
        for pattern in patterns:
            for path in sorted((ROOT / folder).glob(pattern)):
                uri = path.relative_to(ROOT).as_posix()
                files.append(File(uri, str(ROOT), config["site_dir"], config["use_directory_urls"]))
    return files


def _served(target: str, page_dir: str) -> str | None:
    """The site's link for ``target`` (relative to a page in ``docs/page_dir``) when it names a
    served file outside ``docs/``, else None."""
    path, hash_, fragment = target.partition("#")
    if not path or "://" in path or path.startswith(("/", "mailto:")):
        return None
    in_repo = posixpath.normpath(posixpath.join("docs", page_dir, path))
    if not any(in_repo.startswith(folder + "/") for folder in SERVED):
        return None
    return posixpath.relpath(in_repo, page_dir or ".") + hash_ + fragment


def on_page_markdown(markdown: str, page, config, files) -> str:
    page_dir = posixpath.dirname(page.file.src_uri)

    def rewrite(m: re.Match) -> str:
        served = _served(m.group(2), page_dir)
        return m.group(0) if served is None else m.group(1) + served

    return LINK.sub(rewrite, markdown)
