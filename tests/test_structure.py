"""The code's shape: three layers imported only downward, and no module imports one that
imports it back, counting imports inside functions (``TYPE_CHECKING`` blocks aside: they never
run). docs/architecture.md draws the layers."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = {
    "rlenv": ROOT / "rlenv",
    "rlenv_client": ROOT / "client" / "rlenv_client",
    "rlenv_tools": ROOT / "tools" / "rlenv_tools",
}
LAYERS = ["rlenv", "rlenv_client", "rlenv_tools"]
"""The runtime, the client a trainer imports, the tools above both: each imports only below."""
SHARED = ("rlenv", "rlenv.protocol", "rlenv.transport")
"""What the client may import of the runtime: the package's face (its version), the wire."""
EXCEPTIONS = {
    # python -m rlenv is the rlenv command, which is the tools'.
    ("rlenv.__main__", "rlenv_tools.cli"),
    # LocalClient hosts an environment in the trainer's process: the runtime's host, imported
    # inside its functions only when one is made.
    ("rlenv_client.local", "rlenv.serving._host"),
    ("rlenv_client.local", "rlenv.serving.policy_driver"),
    # agents= and others= name an environment's RLAgent classes, and "heuristic" their own policy.
    ("rlenv_client.agent_vector", "rlenv.agent"),
    ("rlenv_client.agent_vector", "rlenv.serving.policy_driver"),
    # RemoteEnv(inspector=True) and RemoteVectorEnv(inspector=True) start the inspector: imported
    # inside __init__, only when asked for.
    ("rlenv_client.env", "rlenv_tools.inspector"),
    ("rlenv_client.vector", "rlenv_tools.inspector"),
}
"""(importer, imported) pairs allowed across the layers' rule, each for the reason above it."""


def _modules() -> dict[str, Path]:
    found = {}
    for package, folder in PACKAGES.items():
        for path in folder.rglob("*.py"):
            parts = [package, *path.relative_to(folder).with_suffix("").parts]
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The project's modules that ``name`` imports when its code runs, anywhere in it."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    type_checking = {
        id(node)
        for block in ast.walk(tree)
        if isinstance(block, ast.If) and getattr(block.test, "id", None) == "TYPE_CHECKING"
        for node in ast.walk(block)
    }

    def known(dotted: str) -> str | None:
        while dotted and dotted not in modules:
            dotted = dotted.rpartition(".")[0]
        return dotted or None

    found = set()
    for node in ast.walk(tree):
        if id(node) in type_checking:
            continue
        if isinstance(node, ast.Import):
            found |= {known(alias.name) for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                package = name if path.name == "__init__.py" else name.rpartition(".")[0]
                for _ in range(node.level - 1):
                    package = package.rpartition(".")[0]
                base = f"{package}.{base}" if base else package
            for alias in node.names:  # a submodule imported by name, or a name of the module
                full = f"{base}.{alias.name}"
                found.add(full if full in modules else known(base))
    return found - {None, name}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected groups of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    groups = []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        for other in graph[module]:
            if other not in index:
                visit(other)
                low[module] = min(low[module], low[other])
            elif other in stack:
                low[module] = min(low[module], index[other])
        if low[module] == index[module]:
            group = []
            while True:
                member = stack.pop()
                group.append(member)
                if member == module:
                    break
            if len(group) > 1:
                groups.append(sorted(group))

    for module in graph:
        if module not in index:
            visit(module)
    return groups


def _crossings(graph: dict[str, set[str]]) -> set[tuple[str, str]]:
    """The imports that break the layers' rule: upward, or the client's of the runtime's inside."""

    def layer(module: str) -> int:
        return LAYERS.index(module.split(".")[0])

    def shared(module: str) -> bool:
        return (
            module == "rlenv"
            or module.startswith(tuple(f"{name}." for name in SHARED[1:]))
            or module in SHARED
        )

    return {
        (importer, imported)
        for importer, imports in graph.items()
        for imported in imports
        if layer(imported) > layer(importer)
        or (
            importer.startswith("rlenv_client")
            and imported.split(".")[0] == "rlenv"
            and not shared(imported)
        )
    }


def test_each_layer_imports_only_the_layers_below_it() -> None:
    modules = _modules()
    graph = {name: _imports(name, path, modules) for name, path in modules.items()}
    serve = graph["rlenv_tools._cli_serve"]  # rlenv serve: both imported inside functions
    assert serve >= {"rlenv_client.launcher", "rlenv.serving.server"}  # both below
    assert _crossings(graph) - EXCEPTIONS == set()
    assert EXCEPTIONS - _crossings(graph) == set()  # no exception outlives its import


def test_the_layers_check_finds_an_upward_import_inside_a_function(tmp_path: Path) -> None:
    sources = {
        "rlenv.node": "def f():\n    from rlenv_tools import cli\n",
        "rlenv.serving._host": "",
        "rlenv.protocol": "",
        "rlenv_client.base": "import rlenv.protocol\n"
        "def g():\n    from rlenv.serving import _host as host\n",
        "rlenv_tools": "",
        "rlenv_tools.cli": "import rlenv.node\nimport rlenv_client.base\n",
    }
    modules = {}
    for name, text in sources.items():
        modules[name] = tmp_path / f"{name}.py"
        modules[name].write_text(text)
    graph = {name: _imports(name, path, modules) for name, path in modules.items()}
    assert graph["rlenv.node"] == {"rlenv_tools.cli"}
    assert _crossings(graph) == {
        ("rlenv.node", "rlenv_tools.cli"),
        ("rlenv_client.base", "rlenv.serving._host"),
    }


def test_importing_the_client_loads_no_tool_no_http_framework_no_onnxruntime() -> None:
    code = "import json, sys\nimport rlenv_client\nprint(json.dumps(sorted(sys.modules)))"
    loaded = set(
        json.loads(
            subprocess.run(
                [sys.executable, "-c", code], check=True, capture_output=True, text=True
            ).stdout
        )
    )
    assert "rlenv_client.client" in loaded
    assert not {
        name
        for name in loaded
        if name.split(".")[0]
        in {
            "rlenv_tools",
            "starlette",
            "uvicorn",
            "httptools",
            "websockets",
            "onnxruntime",
            "onnx",
            "pymunk",
        }
    }
    assert "http.server" not in loaded  # the inspector's server
    runtime = {name for name in loaded if name.split(".")[0] == "rlenv"}
    wire = {name for name in runtime if name.startswith(("rlenv.protocol.", "rlenv.transport."))}
    assert (
        runtime
        - {"rlenv", "rlenv._deprecation", "rlenv._moves", "rlenv.protocol", "rlenv.transport"}
        <= wire
    )
    assert {"rlenv.protocol", "rlenv.transport"} <= runtime


def test_no_module_imports_one_that_imports_it_back() -> None:
    modules = _modules()
    graph = {name: _imports(name, path, modules) for name, path in modules.items()}
    assert graph["rlenv.node"] >= {"rlenv.duplication", "rlenv.views"}
    assert _cycles(graph) == []


def test_the_check_finds_a_circle_through_a_function_level_import(tmp_path: Path) -> None:
    (tmp_path / "a.py").write_text("import b\n")
    (tmp_path / "b.py").write_text("def f():\n    import a\n")
    (tmp_path / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import a\n"
    )
    modules = {name: tmp_path / f"{name}.py" for name in "abc"}
    graph = {name: _imports(name, path, modules) for name, path in modules.items()}
    assert graph == {"a": {"b"}, "b": {"a"}, "c": set()}
    assert _cycles(graph) == [["a", "b"]]


def _documented_modules() -> set[str]:
    pages = (ROOT / "docs" / "reference").glob("*.md")
    return {
        line.removeprefix("::: ").strip()
        for page in pages
        for line in page.read_text().splitlines()
        if line.startswith("::: ")
    }


def _public_modules() -> set[str]:
    """Each module whose dotted name has no part with a leading underscore (packages' faces and
    ``__main__`` aside: a package is public through its ``__init__``, ``-m`` through its main)."""
    public = set()
    for package, folder in PACKAGES.items():
        for path in folder.rglob("*.py"):
            parts = [package, *path.relative_to(folder).with_suffix("").parts]
            if parts[-1] in ("__init__", "__main__"):
                continue
            if not any(part.startswith("_") for part in parts):
                public.add(".".join(parts))
    return public


def test_the_public_modules_are_those_the_reference_documents() -> None:
    documented = _documented_modules()
    assert _public_modules() - documented == set()  # private ones take a leading underscore
    packages = {
        "rlenv.protocol",
        "rlenv.transport",
        "rlenv.scene2d.physics",
        "rlenv_tools.compliance",
    }
    assert {
        name for name in documented if name.count(".")
    } - _public_modules() - packages == set()  # each page's modules exist
