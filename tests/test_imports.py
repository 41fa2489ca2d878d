"""The package's modules form layers: imports run downward between packages, never upward, and
no module imports itself back through a cycle. Every import statement counts (top level,
inside functions, and ``if TYPE_CHECKING`` blocks alike)."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "pickplace"

LAYERS: tuple[tuple[str, ...], ...] = (
    ("cache", "errors", "geometry", "outfile", "signals"),
    ("robot",),
    ("world",),
    ("control",),
    ("planning",),
    ("sim",),
    ("record",),
    ("run",),
    ("sweep",),
    ("cli", "__main__"),
)
"""Bottom to top: a module may import from its own layer's packages and from the layers below.

The bottom layer holds plain modules (errors, geometry, files, signals); each layer above is one
package: the robot (description → composed, calibrated robot), the world (scene, placements),
control (differential IK), planning (grasps → timed, pre-flighted plan), sim (the loop and its
judging, scenarios, loader), record (Rerun), run (one request end to end), sweep (many trials),
and the CLI on top, with the console script's entry (``__main__``: signal handlers, then the
CLI)."""

LAYER_OF = {unit: i for i, layer in enumerate(LAYERS) for unit in layer}


def module_name(path: Path) -> str:
    """``pickplace.planning.plan`` for ``pickplace/planning/plan.py``."""
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def unit_of(module: str) -> str:
    """The layer unit a module belongs to: its package, or the bottom module's own name."""
    return module.split(".")[1] if module.count(".") else ""


@functools.cache
def import_graph() -> dict[str, set[str]]:
    """Module → the pickplace modules it imports, everywhere in its file (parsed once per
    process: do not change it)."""
    graph: dict[str, set[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        name = module_name(path)
        found: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                if node.module == "pickplace":
                    found.update(f"pickplace.{a.name}" for a in node.names)
                elif node.module.startswith("pickplace."):
                    found.add(node.module)
                    # ``from pickplace.sim import faults`` imports the module pickplace.sim.faults
                    found.update(f"{node.module}.{a.name}" for a in node.names)
            elif isinstance(node, ast.Import):
                found.update(a.name for a in node.names if a.name.startswith("pickplace."))
        graph[name] = found - {name}
    modules = set(graph)
    return {m: {n for n in deps if n in modules} for m, deps in graph.items()}


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    """Each import from a higher layer, or from a unit that is in no layer, as ``a -> b``."""
    bad = []
    for m, deps in sorted(graph.items()):
        if m == "pickplace":  # the public API re-exports every layer (lazily)
            continue
        for n in sorted(deps):
            if n == "pickplace":
                bad.append(f"{m} -> {n} (the top-level package, which re-exports everything)")
                continue
            a, b = LAYER_OF.get(unit_of(m)), LAYER_OF.get(unit_of(n))
            if a is None or b is None or b > a:
                bad.append(f"{m} -> {n}")
    return bad


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as a list of modules (first = last), or None."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph.get(m, ())):
            if state.get(n) == 1:
                return [*stack[stack.index(n) :], n]
            if n not in state and (cycle := visit(n)):
                return cycle
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (cycle := visit(m)):
            return cycle
    return None


def test_every_module_belongs_to_a_layer() -> None:
    graph = import_graph()
    assert len(graph) > 30
    units = {unit_of(m) for m in graph if m != "pickplace"}
    assert units <= set(LAYER_OF), sorted(units - set(LAYER_OF))


def test_no_import_runs_upward_between_packages() -> None:
    assert upward_imports(import_graph()) == []


def test_no_import_cycle_among_pickplace_modules() -> None:
    cycle = find_cycle(import_graph())
    assert cycle is None, " -> ".join(cycle or [])


def test_the_checks_see_an_upward_import_and_a_cycle() -> None:
    assert upward_imports({"pickplace.robot.a": {"pickplace.planning.b"}}) == [
        "pickplace.robot.a -> pickplace.planning.b"
    ]
    assert upward_imports({"pickplace.planning.b": {"pickplace.robot.a", "pickplace.errors"}}) == []
    assert upward_imports({"pickplace.geometry": {"pickplace.nowhere.x"}}) != []
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


@pytest.mark.parametrize(
    ("module", "allowed"),
    [
        ("pickplace.geometry", {"pickplace.errors"}),
        ("pickplace.planning.trajectory", {"pickplace.errors", "pickplace.geometry"}),
    ],
)
def test_the_geometry_and_trajectory_sit_at_the_bottom(module: str, allowed: set[str]) -> None:
    """geometry imports nothing of pickplace but errors; the trajectory sits on the two."""
    assert import_graph()[module] <= allowed
