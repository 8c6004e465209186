"""Griffe extension: the docstrings' Sphinx roles become links in the mkdocstrings reference.

rlenv's docstrings are Google style with reStructuredText cross-references
(``:class:`Node```, ``:meth:`~rlenv.tree.SceneTree.iteration```), which Markdown would show as
raw text. When a package has been loaded, every docstring in it is rewritten:

- each role becomes a link to the object it names, resolved as Sphinx would: a dotted path from
  the top package as it is, any other name in the scope of the documented object (its members,
  its parents', the module's imports). A ``~`` shows the last component only. The link is
  *optional*: it is a link where the target is on the site and plain code where it is not (a
  private module, say);
- a name that resolves to nothing in its package is reported as a warning, so ``mkdocs build
  --strict`` fails on a reference that a rename left behind;
- a class attribute declared as ``Signal(...)`` is labelled ``signal`` (not "class-attribute");
- a paragraph ending in ``::`` (a reST literal block follows) ends in ``:``, and a ``::`` alone
  on its line goes: the indented block after it is a Markdown code block already.
"""

from __future__ import annotations

import html
import re
from typing import Any

from griffe import (
    Alias,
    Extension,
    GriffeLoader,
    Module,
    NameResolutionError,
    Object,
    get_logger,
)

logger = get_logger(__name__)

ROLE = re.compile(
    r":(?:py:)?(?:class|meth|func|attr|mod|data|exc|obj):`(?P<tilde>~?)(?P<name>[^`]+)`"
)
LITERAL_ALONE = re.compile(r"(?m)^[ \t]*::[ \t]*\n")
LITERAL_AFTER_TEXT = re.compile(r"(?m)(?<=\S)::[ \t]*$")


class SphinxRoles(Extension):
    """Rewrites the Sphinx roles of every docstring in a loaded package (see the module).

    Args:
        checked: the project's top-level packages: a role naming something in one of them must
            name an object that exists (the package is loaded to check, if need be). Names in
            other packages (gymnasium, numpy ...) are linked as they are written.
    """

    def __init__(self, checked: list[str] | None = None) -> None:
        super().__init__()
        self.checked = frozenset(checked or ())

    def on_package(self, *, pkg: Module, loader: GriffeLoader, **kwargs: Any) -> None:
        """Rewrite the docstrings of ``pkg`` and of every object in it."""
        for obj in _objects(pkg):
            if obj.is_attribute and str(getattr(obj, "value", "")).startswith("Signal("):
                obj.labels = {"signal"}
            docstring = obj.docstring
            if docstring is not None and ("`" in docstring.value or "::" in docstring.value):
                docstring.value = self._rewrite(obj, docstring.value, loader)

    def _rewrite(self, obj: Object, text: str, loader: GriffeLoader) -> str:
        """``text`` with its roles made into links and its literal-block markers into Markdown."""
        text = LITERAL_AFTER_TEXT.sub(":", LITERAL_ALONE.sub("", text))
        return ROLE.sub(lambda match: self._link(obj, match, loader), text)

    def _link(self, obj: Object, match: re.Match[str], loader: GriffeLoader) -> str:
        """An optional autorefs link for one role (plain code, and a warning, if unresolved)."""
        written = re.sub(r"\s+", "", match["name"])
        title, _, target = written.partition("<")
        if target:  # `title <target>`
            target = target.removesuffix(">")
        else:
            target = title.removesuffix("()")
            title = target.rsplit(".", 1)[-1] if match["tilde"] else target
        code = f"<code>{html.escape(title)}</code>"
        path = self._resolve(obj, target.lstrip("."), loader)
        if path is None:
            where = obj.relative_filepath if obj.filepath else obj.path
            logger.warning(
                "%s:%s: the docstring of %s names %r, which does not exist",
                where,
                obj.lineno or 0,
                obj.path,
                target,
            )
            return code
        return f'<autoref optional identifier="{html.escape(path)}">{code}</autoref>'

    def _resolve(self, obj: Object, target: str, loader: GriffeLoader) -> str | None:
        """The full path of ``target`` seen from ``obj``, or ``None`` if it names nothing."""
        first, _, rest = target.partition(".")
        path = _in_scope(obj, first)
        if path is not None:
            path = f"{path}.{rest}" if rest else path
        elif rest:
            path = target  # a full path: `rlenv.protocol.Connection`
        else:
            return None
        top = path.split(".", 1)[0]
        if top not in self.checked:
            return path
        collection = loader.modules_collection
        if top not in collection.members:
            loader.load(top)
        return path if _exists(collection, path) else None


def _in_scope(obj: Object, name: str) -> str | None:
    """The full path of ``name`` in ``obj``'s scope, members inherited by classes included."""
    try:
        return obj.resolve(name)
    except NameResolutionError:
        pass
    scope: Object | None = obj
    while scope is not None:
        if scope.is_class and name in scope.all_members:
            return f"{scope.path}.{name}"
        scope = scope.parent
    return None


def _exists(collection: Any, path: str) -> bool:
    """Whether ``path`` names an object, a member a class inherits included."""
    try:
        collection.get_member(path)
        return True
    except (KeyError, ValueError, AttributeError):
        pass
    owner, _, member = path.rpartition(".")
    try:
        return member in collection[owner].all_members
    except (KeyError, ValueError, AttributeError):
        return False


def _objects(root: Object) -> list[Object]:
    """``root`` and every object defined below it (imported names excluded), in order."""
    found, stack = [], [root]
    while stack:
        obj = stack.pop()
        found.append(obj)
        stack.extend(
            member
            for member in reversed(list(obj.members.values()))
            if not isinstance(member, Alias)
        )
    return found
