"""The public API: every name ``pickplace`` exports resolves, and importing it loads nothing
heavy (the CLI's ``--help`` and ``--version`` pay only for what they use)."""

from __future__ import annotations

import subprocess
import sys

import pytest

import pickplace


@pytest.mark.parametrize("name", [n for n in pickplace.__all__ if n != "__version__"])
def test_every_exported_name_resolves_to_the_object_of_its_module(name: str) -> None:
    module = __import__(pickplace._API[name], fromlist=[name])
    assert getattr(pickplace, name) is getattr(module, name)


def test_an_unknown_name_is_an_attribute_error() -> None:
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        _ = pickplace.no_such_name  # type: ignore[attr-defined]


def test_importing_the_package_imports_neither_mujoco_nor_rerun() -> None:
    code = "import sys, pickplace; print(sorted({'mujoco', 'rerun', 'mink'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
