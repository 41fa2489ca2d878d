"""Packaging: the metadata is in pyproject.toml; this file lists the packages only.

The robot and scene folders are data, mapped into the package as ``pickplace.robots`` and
``pickplace.scenes``; setuptools takes each of their folders whose path is made of Python
identifiers (``menagerie/kuka_iiwa_14/assets``) for a package, and warns about every one a
static list leaves out. The list is therefore made from the folders themselves.
"""

from pathlib import Path

from setuptools import setup

ROOT = Path(__file__).resolve().parent
CODE = ("robot", "world", "control", "planning", "sim", "record", "run", "sweep")
DATA = {"pickplace.scenes": "scenes", "pickplace.robots": "robots"}


def data_packages(package: str, folder: str) -> list[str]:
    """``package`` and a package per folder below ``folder`` whose relative path is made of
    identifiers."""
    root = ROOT / folder
    found = [package]
    for path in sorted(p for p in root.rglob("*") if p.is_dir()):
        parts = path.relative_to(root).parts
        if all(part.isidentifier() for part in parts):
            found.append(".".join((package, *parts)))
    return found


setup(
    packages=[
        "pickplace",
        *(f"pickplace.{name}" for name in CODE),
        *(name for package, folder in DATA.items() for name in data_packages(package, folder)),
    ],
    package_dir=DATA,
)
