"""A robot description: the TOML file a user writes to bring an arm and a gripper.

The file names an arm MJCF file, the body or site where the gripper goes (the flange), the arm's
joint speed limits (no published MJCF file carries them) and optionally its acceleration limits
and home posture; and a gripper MJCF file with its placement on the flange. Everything else the
pipeline needs is read from the files or measured in simulation (``pickplace.robot.compose``)::

    name = "my-arm"                    # shown in summaries and recordings
    [arm]
    mjcf = "arm.xml"                   # path relative to this file
    flange = "hand_mount"              # optional: body or site where the gripper goes
    speed_limits = [2.1, 2.1, 2.1, 2.1, 2.6, 2.6, 2.6]   # rad/s, one per arm joint (required)
    accel_limits = [15, 7.5, 10, 12.5, 15, 20, 20]       # rad/s², optional
    home = [0, 0.3, 0, -1.8, 0, 2.1, 0.8]                # rad, optional (else found by IK)
    angle = "radian"                   # optional: units of a file without <compiler angle>
    base_pos = [0, 0, 0.1]             # optional: the arm's root in the world [m]
    base_quat = [1, 0, 0, 0]           # optional, wxyz
    [gripper]
    mjcf = "gripper.xml"
    mount_pos = [0, 0, 0]              # optional placement on the flange [m]
    mount_quat = [1, 0, 0, 0]          # optional, wxyz
    angle = "radian"
    # optional overrides of what calibration finds:
    pads = [["left_pad"], ["right_pad"]]      # pad geoms of each finger (gripper file names)
    tcp = "grip_site"                         # a site of the gripper file, or
    # tcp = { pos = [0, 0, 0.1], quat = [1, 0, 0, 0] }   # in the gripper's root body frame
    open_command = [0.08]                     # one value per gripper actuator (file order)
    closed_command = [0.0]
    grip_force = 40.0                         # squeeze per jaw grasps are judged by [N]
    squeeze_force = 20.0                      # squeeze per jaw the actuators get [N]
    couple_fingers = true                     # couple independent fingers (default true)

Every bad field raises :class:`~pickplace.errors.RobotError` with one line naming the file, the
field and what would be valid (a long or deep value is quoted shortened). Lengths that depend
on the arm (one speed limit, acceleration limit and home value per arm joint) are checked when
the robot is composed (``pickplace.robot.compose``), with the same kind of message.

Numbers must lie in physical ranges (:data:`SPEED_LIMIT_RANGE`, :data:`ACCEL_LIMIT_RANGE`,
:data:`GRIP_FORCE_RANGE`, :data:`MOUNT_DISTANCE_MAX`): beyond them a value is a unit or typing
error, and the planner's arithmetic (squares of speeds, friction budgets) would overflow.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pickplace.errors import RobotError, file_problem, quoted
from pickplace.robot.mjcf import file_stamps

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

ANGLE_UNITS = ("radian", "degree")
"""Valid values of the ``angle`` fields."""

NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
"""A robot name: letters, digits, '.', '_' and '-' (it appears in recording paths)."""

_TOP_KEYS = ("name", "arm", "gripper")
_ARM_KEYS = (
    "mjcf",
    "flange",
    "speed_limits",
    "accel_limits",
    "home",
    "angle",
    "base_pos",
    "base_quat",
)
_GRIPPER_KEYS = (
    "mjcf",
    "mount_pos",
    "mount_quat",
    "angle",
    "pads",
    "tcp",
    "open_command",
    "closed_command",
    "grip_force",
    "squeeze_force",
    "couple_fingers",
)
_TCP_KEYS = ("pos", "quat")

SPEED_LIMIT_RANGE = (1e-2, 1e2)
"""Joint speed limits [rad/s] (m/s for a slide joint): the fastest arms' joints turn at about
10 rad/s, direct drives at 30; below 0.01 rad/s a radian takes minutes."""
ACCEL_LIMIT_RANGE = (1e-2, 1e4)
"""Joint acceleration limits [rad/s²] (m/s²): arms reach 1–500 rad/s²."""
GRIP_FORCE_RANGE = (0.1, 1e4)
"""A gripper's squeeze per jaw [N]: from a small electric gripper's 1 N to a large pneumatic
one's 5 kN."""
MOUNT_DISTANCE_MAX = 1.0
"""Largest offset of the gripper from the flange, and of the tool point from the gripper, per
axis [m]: more is a unit error (millimetres given as metres)."""
HOME_MAX = 100.0
"""Largest magnitude of a home joint position [rad] (or [m]): 16 turns."""
MAX_DESCRIPTION_BYTES = 1 << 20
"""Largest description file [bytes]: a description is a few hundred bytes."""


def _fail(source: Path, field_name: str, problem: str) -> RobotError:
    return RobotError(f"{source}: {field_name}: {problem}")


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _numbers(
    source: Path,
    field_name: str,
    value: object,
    length: int | None = None,
    what: str = "",
    bounds: tuple[float, float] | None = None,
) -> tuple[float, ...]:
    """A list of finite numbers (of ``length`` if given, each in ``bounds`` if given, in the
    unit ``what``)."""
    shape = f"a list of {length} numbers" if length is not None else "a list of numbers"
    unit = f" {what}" if what else ""
    if not isinstance(value, list) or not all(_is_number(v) for v in value):
        raise _fail(source, field_name, f"must be {shape}{unit}, got {quoted(value)}")
    numbers = tuple(float(v) for v in value)
    if not all(math.isfinite(v) for v in numbers):
        raise _fail(source, field_name, f"must be {shape}{unit}, all finite, got {quoted(value)}")
    if length is not None and len(numbers) != length:
        raise _fail(
            source, field_name, f"must be {shape}{unit}, got {len(numbers)}: {quoted(value)}"
        )
    if not numbers:
        raise _fail(source, field_name, f"must be a non-empty list of numbers{unit}, got []")
    if bounds is not None:
        lo, hi = bounds
        for i, v in enumerate(numbers):
            if not lo <= v <= hi:
                raise _fail(
                    source,
                    field_name,
                    f"value {i + 1} of {len(numbers)} is {v:g}"
                    f"{', not > 0' if v <= 0 < lo else ''}; valid: numbers in "
                    f"[{lo:g}, {hi:g}]{unit}",
                )
    return numbers


def _check_keys(
    source: Path, section: str, table: Mapping[str, Any], valid: tuple[str, ...]
) -> None:
    for key in table:
        if key not in valid:
            where = f"[{section}] {key}" if section else key
            raise _fail(source, where, f"unknown field; valid: {', '.join(valid)}")


def _angle(source: Path, field_name: str, value: object) -> str | None:
    if value is None:
        return None
    if value not in ANGLE_UNITS:
        raise _fail(
            source, field_name, f"must be one of {', '.join(ANGLE_UNITS)}, got {quoted(value)}"
        )
    return str(value)


def _mjcf_path(source: Path, field_name: str, value: object) -> Path:
    if not isinstance(value, str) or not value:
        raise _fail(source, field_name, f"must be a path to an MJCF file, got {quoted(value)}")
    path = Path(value)
    path = (source.parent / path).resolve() if not path.is_absolute() else path
    problem = file_problem(path)
    if problem is not None:
        raise _fail(
            source,
            field_name,
            f"'{path}' {problem}; valid: an MJCF file path relative to '{source.parent}'",
        )
    return path


def check_speed_limits(source: Path, limits: tuple[float, ...], joints: tuple[str, ...]) -> None:
    """Raise unless there is one positive speed limit per arm joint.

    Args:
        source: The description file (for the message).
        limits: The ``[arm] speed_limits`` values [rad/s].
        joints: The arm's joints, root to flange.
    """
    _check_per_joint(source, "[arm] speed_limits", limits, joints, "rad/s", positive=True)


def _check_per_joint(
    source: Path,
    field_name: str,
    values: tuple[float, ...],
    joints: tuple[str, ...],
    unit: str,
    positive: bool,
) -> None:
    kind = "positive numbers" if positive else "numbers"
    valid = f"{len(joints)} {kind} [{unit}], one per arm joint ({', '.join(joints)})"
    if len(values) != len(joints):
        raise _fail(source, field_name, f"has {len(values)} values; valid: {valid}")
    if positive and any(v <= 0 for v in values):
        raise _fail(source, field_name, f"{quoted(list(values))} is not all > 0; valid: {valid}")


def check_per_joint(
    source: Path, field_name: str, values: tuple[float, ...], joints: tuple[str, ...], unit: str
) -> None:
    """Raise unless ``values`` has one number per arm joint (any sign)."""
    _check_per_joint(source, field_name, values, joints, unit, positive=False)


@dataclass(frozen=True)
class TcpOverride:
    """A tool point given instead of calibrated: a site of the gripper file, or a pose.

    Attributes:
        site: Name of a site in the gripper file whose frame is the tool frame, or None.
        pos: Position in the gripper's root body frame [m] (when ``site`` is None).
        quat: Orientation wxyz in the gripper's root body frame (when ``site`` is None).
    """

    site: str | None = None
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class ArmDescription:
    """The ``[arm]`` table.

    Attributes:
        mjcf: The arm's MJCF file (resolved).
        flange: Body or site of the arm file where the gripper goes, or None: the site
            ``attachment_site`` if the file has one, else the last body of the chain.
        speed_limits: Joint speed limits [rad/s], one per arm joint, root to flange.
        accel_limits: Joint acceleration limits [rad/s²], or None.
        home: Home posture [rad], or None (then found by IK).
        angle: Units of a file without ``<compiler angle>``, or None.
        base_pos: Position of the arm's root frame in the world [m], or None: at the origin,
            raised just enough that no geom of its base touches the floor.
        base_quat: Orientation (wxyz, unit) of the arm's root frame in the world.
    """

    mjcf: Path
    flange: str | None
    speed_limits: tuple[float, ...]
    accel_limits: tuple[float, ...] | None = None
    home: tuple[float, ...] | None = None
    angle: str | None = None
    base_pos: tuple[float, float, float] | None = None
    base_quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class GripperDescription:
    """The ``[gripper]`` table.

    Attributes:
        mjcf: The gripper's MJCF file (resolved).
        mount_pos: Position of the gripper's root frame on the flange [m].
        mount_quat: Orientation (wxyz, unit) of the gripper's root frame on the flange.
        angle: Units of a file without ``<compiler angle>``, or None.
        pads: Pad geoms of each finger (names in the gripper file), or None (calibrated).
        tcp: Tool point, or None (calibrated).
        open_command: Open command, one value per actuator of the gripper file, or None.
        closed_command: Closed command, likewise, or None.
        grip_force: Squeeze per jaw [N] to judge grasps against, or None (measured).
        squeeze_force: Squeeze per jaw [N] the gripper is given, or None (its files'): the
            actuators' force ranges scale by it over the measured squeeze, their gains too
            when it is larger (as ``--vary grip_force`` does), before calibration.
        couple_fingers: Couple independently actuated fingers (tendon + joint equality).
    """

    mjcf: Path
    mount_pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mount_quat: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    angle: str | None = None
    pads: tuple[tuple[str, ...], tuple[str, ...]] | None = None
    tcp: TcpOverride | None = None
    open_command: tuple[float, ...] | None = None
    closed_command: tuple[float, ...] | None = None
    grip_force: float | None = None
    squeeze_force: float | None = None
    couple_fingers: bool = True


_DESCRIPTIONS: dict[Path, tuple[tuple[tuple[str, int, int], ...], RobotDescription]] = {}


@dataclass(frozen=True)
class RobotDescription:
    """A robot: an arm, a gripper on its flange, and the data no MJCF file carries.

    Attributes:
        source: The description file (named in every error message).
        name: Robot name (letters, digits, '.', '_', '-').
        arm: The ``[arm]`` table.
        gripper: The ``[gripper]`` table.
    """

    source: Path
    name: str
    arm: ArmDescription
    gripper: GripperDescription = field(repr=False)

    @classmethod
    def from_toml(cls, path: str | Path) -> RobotDescription:
        """Read and validate a description file.

        Raises:
            RobotError: The file is missing or not TOML, or a field is missing or invalid;
                one line naming the file, the field and what would be valid.
        """
        source = Path(path).resolve()
        stamps = file_stamps([source])
        known = _DESCRIPTIONS.get(source)
        if known is not None and stamps is not None and known[0] == stamps:
            return known[1]  # unchanged since it was read (a description is immutable)
        desc = cls._read(source)
        if stamps is not None:
            _DESCRIPTIONS[source] = (stamps, desc)
        return desc

    @classmethod
    def _read(cls, source: Path) -> RobotDescription:
        problem = file_problem(source)
        if problem is not None:
            raise RobotError(
                f"{source}: robot description {problem}; valid: a TOML file with "
                f"name, [arm] and [gripper] (see docs/robots.md)"
            )
        size = source.stat().st_size
        if size > MAX_DESCRIPTION_BYTES:
            raise RobotError(
                f"{source}: robot description is {size} bytes; valid: at most "
                f"{MAX_DESCRIPTION_BYTES} bytes (a description is a few hundred)"
            )
        try:
            table = tomllib.loads(source.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            detail = " ".join(str(exc).split())
            raise RobotError(f"{source}: not valid TOML: {quoted(detail)}") from exc
        except RecursionError:  # the parser recurses into nested arrays and tables
            raise RobotError(
                f"{source}: not valid TOML here: arrays or tables nested thousands deep; "
                "valid: a description's few levels (see docs/robots.md)"
            ) from None
        return cls.from_mapping(table, source)

    @classmethod
    def from_mapping(cls, table: Mapping[str, Any], source: Path) -> RobotDescription:
        """Validate a parsed description (``source`` is named in errors and anchors paths)."""
        _check_keys(source, "", table, _TOP_KEYS)
        name = table.get("name")
        if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
            raise _fail(
                source,
                "name",
                f"must be letters, digits, '.', '_' or '-' (not starting with a symbol), "
                f"got {quoted(name)}",
            )
        for section in ("arm", "gripper"):
            if not isinstance(table.get(section), dict):
                raise _fail(source, f"[{section}]", "missing table; valid: see docs/robots.md")
        return cls(
            source=source,
            name=name,
            arm=_parse_arm(source, table["arm"]),
            gripper=_parse_gripper(source, table["gripper"]),
        )


def _parse_arm(source: Path, t: Mapping[str, Any]) -> ArmDescription:
    _check_keys(source, "arm", t, _ARM_KEYS)
    for key in ("mjcf", "speed_limits"):
        if key not in t:
            raise _fail(source, f"[arm] {key}", "missing (required)")
    flange = t.get("flange")
    if flange is not None and (not isinstance(flange, str) or not flange):
        raise _fail(source, "[arm] flange", f"must be a body or site name, got {quoted(flange)}")
    speed = _numbers(
        source, "[arm] speed_limits", t["speed_limits"], what="[rad/s]", bounds=SPEED_LIMIT_RANGE
    )
    accel = None
    if "accel_limits" in t:  # one per arm joint, like the speed limits: checked at composing
        accel = _numbers(
            source,
            "[arm] accel_limits",
            t["accel_limits"],
            what="[rad/s²]",
            bounds=ACCEL_LIMIT_RANGE,
        )
    home = None
    if "home" in t:
        home = _numbers(source, "[arm] home", t["home"], what="[rad]", bounds=(-HOME_MAX, HOME_MAX))
    return ArmDescription(
        mjcf=_mjcf_path(source, "[arm] mjcf", t["mjcf"]),
        flange=flange,
        speed_limits=speed,
        accel_limits=accel,
        home=home,
        angle=_angle(source, "[arm] angle", t.get("angle")),
        base_pos=_vec3(source, "[arm] base_pos", t["base_pos"]) if "base_pos" in t else None,
        base_quat=_unit_quat(source, "[arm] base_quat", t.get("base_quat", [1, 0, 0, 0])),
    )


def _unit_quat(source: Path, field_name: str, value: object) -> tuple[float, float, float, float]:
    q = _numbers(source, field_name, value, 4, "(wxyz)")
    norm = math.sqrt(sum(v * v for v in q))
    if norm < 1e-9:
        raise _fail(
            source, field_name, f"must be a non-zero quaternion (wxyz), got {quoted(value)}"
        )
    w, x, y, z = (v / norm for v in q)
    return (w, x, y, z)


def _vec3(source: Path, field_name: str, value: object) -> tuple[float, float, float]:
    bound = (-MOUNT_DISTANCE_MAX, MOUNT_DISTANCE_MAX)
    x, y, z = _numbers(source, field_name, value, 3, "[m]", bounds=bound)
    return (x, y, z)


def _parse_gripper(source: Path, t: Mapping[str, Any]) -> GripperDescription:
    _check_keys(source, "gripper", t, _GRIPPER_KEYS)
    if "mjcf" not in t:
        raise _fail(source, "[gripper] mjcf", "missing (required)")
    pads = None
    if "pads" in t:
        value = t["pads"]
        valid = 'two lists of geom names, one per finger, e.g. [["left_pad"], ["right_pad"]]'
        if (
            not isinstance(value, list)
            or len(value) != 2
            or not all(isinstance(side, list) and side for side in value)
            or not all(isinstance(n, str) and n for side in value for n in side)
        ):
            raise _fail(source, "[gripper] pads", f"got {quoted(value)}; valid: {valid}")
        pads = (tuple(value[0]), tuple(value[1]))
    tcp = None
    if "tcp" in t:
        value = t["tcp"]
        if isinstance(value, str) and value:
            tcp = TcpOverride(site=value)
        elif isinstance(value, dict):
            _check_keys(source, "gripper.tcp", value, _TCP_KEYS)
            tcp = TcpOverride(
                pos=_vec3(source, "[gripper] tcp.pos", value.get("pos", [0.0, 0.0, 0.0])),
                quat=_unit_quat(source, "[gripper] tcp.quat", value.get("quat", [1, 0, 0, 0])),
            )
        else:
            raise _fail(
                source,
                "[gripper] tcp",
                f"got {quoted(value)}; valid: a site name or "
                "{ pos = [x, y, z], quat = [w, x, y, z] }",
            )
    commands: dict[str, tuple[float, ...] | None] = {}
    for key in ("open_command", "closed_command"):
        commands[key] = _numbers(source, f"[gripper] {key}", t[key]) if key in t else None
    forces: dict[str, float | None] = {}
    lo, hi = GRIP_FORCE_RANGE
    for key in ("grip_force", "squeeze_force"):
        value = t.get(key)
        if value is not None and (not _is_number(value) or not lo <= value <= hi):
            raise _fail(
                source,
                f"[gripper] {key}",
                f"is {quoted(value)}; valid: a number in [{lo:g}, {hi:g}] [N] (squeeze per jaw)",
            )
        forces[key] = None if value is None else float(value)
    couple = t.get("couple_fingers", True)
    if not isinstance(couple, bool):
        raise _fail(
            source, "[gripper] couple_fingers", f"must be true or false, got {quoted(couple)}"
        )
    return GripperDescription(
        mjcf=_mjcf_path(source, "[gripper] mjcf", t["mjcf"]),
        mount_pos=_vec3(source, "[gripper] mount_pos", t.get("mount_pos", [0.0, 0.0, 0.0])),
        mount_quat=_unit_quat(source, "[gripper] mount_quat", t.get("mount_quat", [1, 0, 0, 0])),
        angle=_angle(source, "[gripper] angle", t.get("angle")),
        pads=pads,
        tcp=tcp,
        open_command=commands["open_command"],
        closed_command=commands["closed_command"],
        grip_force=forces["grip_force"],
        squeeze_force=forces["squeeze_force"],
        couple_fingers=couple,
    )
