"""Imports flow one way: ``db`` <- ``ingest`` <- ``animegraph``, and inside ``animegraph``
from room to room in the order its package docstring gives."""

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
    "apps": {"motion", "search", "emotion", "face", "baselines", "synthesis"},
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
