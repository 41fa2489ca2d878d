"""The parameters a sweep can vary (``--vary NAME=...``): names, units, valid ranges, meaning.

Importable without numpy, so that ``pickplace --help`` can list them at once; how values are
drawn is :mod:`pickplace.sim.vary`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pickplace.errors import InvalidInputError

# The runner's accepted control rates [Hz]: pickplace.run.runner.CONTROL_RATE_RANGE_HZ, repeated
# rather than imported so that the runner may import this module (a test checks they agree).
_CONTROL_RATE_HZ = (100.0, 1000.0)


@dataclass(frozen=True)
class Parameter:
    """A parameter a sweep can vary.

    Attributes:
        name: Canonical name, e.g. ``brick_mass``.
        unit: Unit of its values (``-`` for a dimensionless factor).
        low: Smallest valid value.
        high: Largest valid value.
        meaning: What the value is, in one line.
        grid_only: Whether only a grid of values is allowed (a discrete parameter).
        whole: Whether its values must be whole numbers (a count).
    """

    name: str
    unit: str
    low: float
    high: float
    meaning: str
    grid_only: bool = False
    whole: bool = False

    def __post_init__(self) -> None:
        """Check that the bounds are finite and ordered."""
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise InvalidInputError(
                f"parameter {self.name}: bounds must be finite with low < high, got "
                f"[{self.low}, {self.high}]"
            )

    def describe(self) -> str:
        """``name [unit] in [low, high]``, as listed in error messages."""
        grid = (", grid only" if self.grid_only else "") + (", whole" if self.whole else "")
        return f"{self.name} [{self.unit}] in [{self.low:g}, {self.high:g}]{grid}"


PARAMETERS: dict[str, Parameter] = {
    p.name: p
    for p in (
        Parameter("brick_mass", "kg", 0.01, 100.0, "mass of the brick; its inertia scales with it"),
        Parameter(
            "brick_size",
            "-",
            0.5,
            1.5,
            "scale factor of the brick's three edge lengths (1 = the scene's brick)",
        ),
        Parameter("friction", "-", 0.05, 2.0, "sliding friction coefficient brick-pads"),
        Parameter("grip_force", "N", 1.0, 200.0, "gripper force limit (squeeze per jaw)"),
        Parameter(
            "pose_noise",
            "m",
            0.0,
            0.1,
            "distance the brick is moved after planning, in a direction drawn from the seed",
        ),
        Parameter(
            "speed",
            "-",
            0.1,
            1.0,
            "fraction of the planner's speed limits (accelerations scale by its square)",
        ),
        Parameter(
            "control_rate",
            "Hz",
            *_CONTROL_RATE_HZ,
            "IK rate; must divide the physics rate (100, 125, 250, 500 Hz at 2 ms steps)",
            grid_only=True,
        ),
        Parameter(
            "divider_height",
            "m",
            0.0,
            0.6,
            "height of a divider wall between the bins (0: none)",
        ),
        Parameter(
            "shelf_height",
            "m",
            0.0,
            1.2,
            "height of the underside of a shelf over bin 2 (0: none)",
        ),
        Parameter(
            "obstacle_boxes",
            "-",
            0.0,
            6.0,
            "number of boxes standing at random in the workspace, drawn from the seed",
            grid_only=True,
            whole=True,
        ),
        Parameter(
            "attempts",
            "-",
            1.0,
            10.0,
            "most attempts of a run: after a missed grasp or a drop it plans again (whole numbers)",
            grid_only=True,
            whole=True,
        ),
    )
}


def valid_parameters() -> str:
    """The valid names with units and ranges, as one line for error messages."""
    return "; ".join(p.describe() for p in PARAMETERS.values())


def get_parameter(name: str) -> Parameter:
    """The parameter called ``name`` (``-`` is read as ``_``).

    Raises:
        InvalidInputError: Unknown name; the message lists the valid names, units and ranges.
    """
    key = name.strip().replace("-", "_")
    if key not in PARAMETERS:
        raise InvalidInputError(f"--vary: unknown parameter '{name}'; valid: {valid_parameters()}")
    return PARAMETERS[key]


__all__ = ["PARAMETERS", "Parameter", "get_parameter", "valid_parameters"]
