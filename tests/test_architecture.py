"""The package's own code uses libraries, and its own modules, only through public names.

A private name is one with a leading underscore that is not a dunder (``_x``, not ``__x__``).
Reading ``something._x`` off anything other than ``self`` or ``cls`` reaches into another
object's internals (mink's, mujoco's, daqp's, or another pickplace class's); so does importing
``_x`` from another module. Both break silently when the other side changes.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "pickplace"
MODULES = sorted(PACKAGE.rglob("*.py"))
OWN_NAMES = ("self", "cls")
# Public names that happen to start with an underscore: os._exit is the documented way to end a
# process without running exit handlers.
PUBLIC_EXCEPTIONS = {"os._exit"}


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_uses(source: str) -> list[str]:
    """Each foreign private attribute read or private name imported in ``source``.

    Returns:
        ``"line: text"`` per use, in source order.
    """
    found: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and _is_private(node.attr):
            owner = node.value
            if isinstance(owner, ast.Name) and owner.id in OWN_NAMES:
                continue
            if ast.unparse(node) not in PUBLIC_EXCEPTIONS:
                found.append((node.lineno, ast.unparse(node)))
        elif isinstance(node, ast.ImportFrom):
            for alias in node.names:
                if _is_private(alias.name):
                    found.append((node.lineno, f"from {node.module} import {alias.name}"))
    return [f"{line}: {text}" for line, text in sorted(found)]


@pytest.mark.parametrize("path", MODULES, ids=[str(p.relative_to(PACKAGE)) for p in MODULES])
def test_no_private_attribute_of_another_object_is_used(path: Path) -> None:
    assert private_uses(path.read_text()) == []


def test_the_scan_sees_foreign_privates_and_allows_own_ones() -> None:
    source = """
from mink.lie import _lie_ops_c
from pickplace.world.scene import Scene, _helper
task._error_and_jacobian(cfg)
self.task._cache
x = self._mine + cls._also_mine + self.__class__.__name__ + obj.__dict__
"""
    assert private_uses(source) == [
        "2: from mink.lie import _lie_ops_c",
        "3: from pickplace.world.scene import _helper",
        "4: task._error_and_jacobian",
        "5: self.task._cache",
    ]


def test_the_package_has_modules_to_scan() -> None:
    assert {"controllers.py", "recording.py", "loop.py"} <= {p.name for p in MODULES}
