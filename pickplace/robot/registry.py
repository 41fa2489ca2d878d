"""Where robots come from: the bundled ones by name, a ``robot.toml`` path, or a description;
and the digest of everything a robot is made of."""

from __future__ import annotations

import hashlib
from pathlib import Path

from pickplace.errors import RobotError
from pickplace.robot import DEFAULT_ROBOT  # re-exported: where robots come from names it
from pickplace.robot.description import RobotDescription


def _robots_dir() -> Path:
    """``robots/`` of a source checkout, or the copy installed as ``pickplace/robots``."""
    here = Path(__file__).resolve().parent.parent  # pickplace/
    for candidate in (here.parent / "robots", here / "robots"):
        if candidate.is_dir():
            return candidate
    return here.parent / "robots"


def _world_path() -> Path:
    here = Path(__file__).resolve().parent.parent  # pickplace/
    for candidate in (here.parent / "scenes", here / "scenes"):
        if (candidate / "world.xml").is_file():
            return candidate / "world.xml"
    return here.parent / "scenes" / "world.xml"


ROBOTS_DIR = _robots_dir()
DEFAULT_WORLD = _world_path()


def bundled_robots() -> list[str]:
    """Names of the robots shipped in ``robots/`` (folders holding a ``robot.toml``)."""
    return sorted(p.parent.name for p in ROBOTS_DIR.glob("*/robot.toml"))


def resolve_description(robot: str | Path | RobotDescription) -> RobotDescription:
    """A description from a bundled robot's name, a ``.toml`` path, a folder holding a
    ``robot.toml`` (a bundled robot's copy, ``robots/panda-hand``), or itself.

    Raises:
        RobotError: The name is not bundled and no such file exists (lists the bundled names),
            or the folder holds no ``robot.toml``.
    """
    if isinstance(robot, RobotDescription):
        return robot
    text = str(robot)
    if text in bundled_robots():
        return RobotDescription.from_toml(ROBOTS_DIR / text / "robot.toml")
    path = Path(text)
    if path.is_dir():
        toml = path / "robot.toml"
        if not toml.is_file():
            raise RobotError(
                f"robot folder '{path}' holds no robot.toml; valid: {', '.join(bundled_robots())}, "
                "a robot.toml path or a folder holding one"
            )
        return RobotDescription.from_toml(toml)
    if path.suffix == ".toml" or path.exists():
        return RobotDescription.from_toml(path)
    raise RobotError(
        f"unknown robot '{text}'; valid: {', '.join(bundled_robots())}, a robot.toml path or a "
        "folder holding one"
    )


def description_digest(desc: RobotDescription) -> str:
    """SHA-256 of what a robot is made of: its description and the arm and gripper files with
    their includes and assets (read, not loaded into MuJoCo).

    Raises:
        RobotError: A file it names is missing.
    """
    # Imported here: MuJoCo (and numpy) load only when a robot is, not with this module (the
    # CLI imports it before it installs its signal handlers).
    from pickplace.robot.mjcf import part_digest

    # The parsed description (every field), and its path: messages name the file.
    digest = hashlib.sha256(repr((desc.source, desc.name, desc.arm, desc.gripper)).encode())
    for mjcf, field_name, angle in (
        (desc.arm.mjcf, "[arm] mjcf", desc.arm.angle),
        (desc.gripper.mjcf, "[gripper] mjcf", desc.gripper.angle),
    ):
        digest.update(part_digest(mjcf, field_name, angle, desc.source).encode())
    return digest.hexdigest()


__all__ = [
    "DEFAULT_ROBOT",
    "DEFAULT_WORLD",
    "ROBOTS_DIR",
    "bundled_robots",
    "description_digest",
    "resolve_description",
]
