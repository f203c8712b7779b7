"""Imports flow one way: ``db`` <- ``ingest`` <- ``animegraph``, and inside ``animegraph``
from room to room in the order its package docstring gives; no modules import each other
in a circle, and none is long."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# What each package may import of the project's own packages.
ALLOWED = {"db": {"db"}, "ingest": {"db", "ingest"}, "animegraph": {"db", "ingest", "animegraph"}}
# What each room of animegraph may import of the other rooms (its own always).
ROOMS = {
    "motion": set(),
    "search": set(),
    "emotion": set(),
    "face": {"motion"},
    "baselines": {"motion"},
    "synthesis": {"motion", "search", "emotion"},
    "live": {"motion", "search", "emotion", "face", "baselines", "synthesis"},
    "apps": {"motion", "search", "emotion", "face", "baselines", "synthesis", "live"},
}


def _imports(path: Path) -> set[str]:
    """Dotted names of the project's modules (and imported names) that ``path`` imports."""
    tree = ast.parse(path.read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names |= {f"{node.module}.{a.name}" for a in node.names}
    return {n for n in names if n.split(".")[0] in ALLOWED}


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_layering(package):
    for path in sorted((ROOT / package).rglob("*.py")):
        bad = {n.split(".")[0] for n in _imports(path)} - ALLOWED[package]
        assert not bad, f"{path.relative_to(ROOT)} imports {sorted(bad)}"


def test_animegraph_is_rooms_only():
    # Every module lives in a room; the package itself holds only its public names.
    loose = {p.name for p in (ROOT / "animegraph").glob("*.py")} - {"__init__.py", "__main__.py"}
    assert not loose, f"modules outside a room: {sorted(loose)}"
    rooms = {p.name for p in (ROOT / "animegraph").iterdir() if (p / "__init__.py").exists()}
    assert rooms == set(ROOMS), f"rooms {sorted(rooms)} differ from the documented {sorted(ROOMS)}"


@pytest.mark.parametrize("room", sorted(ROOMS))
def test_rooms_import_one_way(room):
    for path in sorted((ROOT / "animegraph" / room).rglob("*.py")):
        used = {n.split(".")[1] for n in _imports(path)
                if n.startswith("animegraph.") and n.split(".")[1] in ROOMS}
        bad = used - ROOMS[room] - {room}
        assert not bad, f"{path.relative_to(ROOT)} imports rooms {sorted(bad)}"


def test_the_room_order_has_no_cycle():
    order = []
    todo = dict(ROOMS)
    while todo:
        ready = [r for r, deps in todo.items() if deps <= set(order)]
        assert ready, f"rooms import each other in a cycle: {sorted(todo)}"
        order += sorted(ready)
        for r in ready:
            del todo[r]


def test_scripts_hold_no_library_code():
    # scripts/ are thin drivers: no classes of their own.
    for path in sorted((ROOT / "scripts").glob("*.py")):
        tree = ast.parse(path.read_text())
        assert not [n for n in tree.body if isinstance(n, ast.ClassDef)], path.name


def test_public_names_import_from_the_package():
    # The names users import keep working whatever room they live in.
    import animegraph

    for name in animegraph.__all__:
        assert getattr(animegraph, name) is not None, name
    assert callable(animegraph.synthesize)
    assert hasattr(animegraph.MuMlp(), "fit")
    with pytest.raises(AttributeError):
        animegraph.no_such_name  # noqa: B018


#: The packages whose modules may not import each other in a circle.
PACKAGES = ("db", "ingest", "animegraph")
#: Longest module, in lines (the project's standard: small modules).
MAX_LINES = 800


def _module_files() -> dict[str, Path]:
    """Dotted module name -> file, for every module of :data:`PACKAGES`."""
    modules = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


def _import_graph() -> dict[str, set[str]]:
    """Module -> the project's modules it imports: every import statement, at the top, in a
    function (a lazy import is as much a dependency) or under ``TYPE_CHECKING``, relative
    ones resolved. ``from a.b import c`` is a dependency on ``a.b.c`` if that is a module,
    else on ``a.b``."""
    modules = _module_files()

    def owner(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([node.module] if node.module else []))
                targets |= {f"{base}.{a.name}" for a in node.names}
        graph[name] = {m for m in map(owner, targets) if m is not None} - {name}
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_circle_finder_finds_a_circle():
    # a -> b -> c -> a, and d alone: one circle of three.
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _circles({"a": {"b"}, "b": set()}) == []


def test_no_import_circle():
    # A circle of imports, even through an import inside a function, makes the modules
    # one: none can be read, tested or moved without the others.
    circles = _circles(_import_graph())
    assert not circles, "modules import each other in a circle: " + "; ".join(
        " <-> ".join(c) for c in circles)


def test_no_module_is_long():
    # The project's code and its scripts (tests are not modules of the project).
    files = [*_module_files().values(), *sorted((ROOT / "scripts").glob("*.py"))]
    long = {str(path.relative_to(ROOT)): n for path in files
            if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"
