"""MkDocs hooks: the README is the home page, and links out of ``docs/`` read as plain text.

- ``index.md`` is generated from ``README.md`` at build time, and ``changelog.md`` from
  ``CHANGELOG.md`` (nothing is copied into ``docs/``, so they never drift apart); their links
  into ``docs/`` are made relative to the site, and the README's to the changelog lead to its
  page.
- A link to a folder of ``docs/`` that holds a ``README.md`` leads to it (a repository browser
  shows it there; on the site it is that folder's page).
- A link from a page to a file outside ``docs/`` (``../../../tests/protocol_vectors.py``) works
  on a repository browser but not on the site, which holds no source files: it is replaced by
  its text, which names the file already.
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import File, Files
from mkdocs.structure.pages import Page

LINK = re.compile(r"(?<!!)\[(?P<text>[^\]]+)\]\((?P<target>[^)\s]+)\)")


def on_files(files: Files, config: MkDocsConfig) -> Files:
    """Add ``index.md`` and ``changelog.md``, made from the README and the changelog."""
    root = Path(config.config_file_path).parent
    for source, page in (("README.md", "index.md"), ("CHANGELOG.md", "changelog.md")):
        text = (root / source).read_text(encoding="utf-8").replace("](docs/", "](")
        text = text.replace("](CHANGELOG.md", "](changelog.md")
        files.append(File.generated(config, page, content=text))
    return files


def on_page_markdown(markdown: str, page: Page, config: MkDocsConfig, **kwargs: object) -> str:
    """``markdown`` with its links to folders and to files outside ``docs/`` made to work."""
    folder = posixpath.dirname(page.file.src_uri)
    docs = Path(config.docs_dir)

    def fix(match: re.Match[str]) -> str:
        target = match["target"]
        if "://" in target or target.startswith(("#", "/", "mailto:")):
            return match[0]
        path = posixpath.normpath(posixpath.join(folder, target.split("#", 1)[0]))
        if path.startswith("../") or path == "..":
            return match["text"]
        if target.endswith("/") and (docs / path / "README.md").is_file():
            return f"[{match['text']}]({target}README.md)"
        return match[0]

    return LINK.sub(fix, markdown)
