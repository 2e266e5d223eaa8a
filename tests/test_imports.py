"""The package's imports, read with `ast` (nothing is imported): the module-level darthand imports form no cycle,
and a darthand import inside a function says why it is there.

A module-level import is one that runs when the module is imported: at the top, or inside a module-level `if`,
`try` or class body, but not under `if TYPE_CHECKING:`. A function-level import must carry a comment on its line(s)
or the line above (`# lazy: pxr takes 0.4 s to import`, `# lazy: a cycle through ...`); a stage's commands module
(commands.py, commands_*.py) says once, in its docstring, that its handlers import what they use lazily.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "tools" / "darthand"

BLOCKS = (ast.Try, getattr(ast, "TryStar", ast.Try), ast.With, ast.ClassDef, ast.For, ast.While)
PRAGMA = re.compile(r"#\s*(noqa|type:|pragma|pylint|fmt:)", re.IGNORECASE)


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def targets(node: ast.Import | ast.ImportFrom, known: dict[str, Path]) -> list[str]:
    """The darthand modules an import statement imports (`from pkg import sub` names the submodule too; the package
    imports absolutely, so a relative import names none)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name.split(".")[0] == "darthand"]
    source = node.module or ""
    if node.level or source.split(".")[0] != "darthand":
        return []
    return [source] + [f"{source}.{a.name}" for a in node.names if f"{source}.{a.name}" in known]


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def module_level_imports(tree: ast.Module):
    """Import statements that run when the module is imported."""
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif isinstance(node, ast.If):
            stack += node.orelse if _is_type_checking(node) else node.body + node.orelse
        elif isinstance(node, BLOCKS):
            for field in ("body", "orelse", "finalbody"):
                stack += getattr(node, field, [])
            stack += [s for h in getattr(node, "handlers", []) for s in h.body]


def function_level_imports(tree: ast.Module) -> list[ast.stmt]:
    """Import statements inside a function (at any depth), each once."""
    found = {}
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            found.update((id(n), n) for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom)))
    return sorted(found.values(), key=lambda n: n.lineno)


def import_graph() -> dict[str, set[str]]:
    known = modules()
    graph = {}
    for name, path in known.items():
        tree = ast.parse(path.read_text(), str(path))
        graph[name] = {t for node in module_level_imports(tree) for t in targets(node, known)
                       if t in known and t != name}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of `graph` as [a, b, ..., a], or None (iterative depth-first search, white/grey/black)."""
    colour = dict.fromkeys(graph, 0)
    for root in sorted(graph):
        if colour[root]:
            continue
        path, iters = [root], [iter(sorted(graph[root]))]
        colour[root] = 1
        while iters:
            nxt = next(iters[-1], None)
            if nxt is None:
                colour[path.pop()] = 2
                iters.pop()
            elif colour[nxt] == 1:
                return path[path.index(nxt):] + [nxt]
            elif colour[nxt] == 0:
                colour[nxt] = 1
                path.append(nxt)
                iters.append(iter(sorted(graph[nxt])))
    return None


def _commented(lines: list[str], node: ast.stmt) -> bool:
    span = lines[node.lineno - 1:node.end_lineno]
    above = lines[node.lineno - 2].strip() if node.lineno > 1 else ""
    comments = [line[line.index("#"):] for line in span if "#" in line]
    if above.startswith("#"):
        comments.append(above)
    return any(not PRAGMA.match(c) for c in comments)


def _says_lazily(path: Path) -> bool:
    """A stage's commands module (commands.py, commands_*.py, manifest_commands.py) or cli.py: their imports inside
    handlers keep each command's start-up to what it uses, said once in the docstring."""
    return bool(re.fullmatch(r"(\w+_)?commands(_\w+)?\.py|cli\.py", path.name))


def uncommented_lazy_imports() -> list[str]:
    found, known = [], modules()
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if _says_lazily(path):
            continue
        text = path.read_text()
        tree = ast.parse(text, str(path))
        lines = text.splitlines()
        found += [f"{rel}:{node.lineno}: {lines[node.lineno - 1].strip()}"
                  for node in function_level_imports(tree) if targets(node, known)
                  and not _commented(lines, node)]
    return found


def test_module_level_imports_have_no_cycle():
    graph = import_graph()
    assert len(graph) > 100 and graph["darthand.model.mano_pkl"] >= {"darthand.safe_pickle"}
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_find_cycle_finds_one():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_commands_modules_say_their_imports_are_lazy():
    for path in sorted(p for p in PACKAGE.rglob("*.py") if _says_lazily(p)):
        rel = path.relative_to(PACKAGE).as_posix()
        tree = ast.parse(path.read_text(), str(path))
        if not any(targets(n, modules()) for n in function_level_imports(tree)):
            continue
        assert "lazily" in (ast.get_docstring(tree) or ""), f"{rel}: the docstring does not say why imports are lazy"


def test_function_level_imports_say_why():
    found = uncommented_lazy_imports()
    assert not found, "function-level darthand imports without a comment saying why:\n" + "\n".join(found)
