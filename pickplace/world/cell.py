"""What stands in the cell besides the bins and the brick: the world parameters of an obstacle
cell (the divider's and the shelf's heights, the boxes), as plain values.

:mod:`pickplace.world.obstacles` states their geometry and adds them to a scene.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pickplace.errors import InvalidInputError

MAX_BOXES = 6
"""Most boxes a cell holds."""


@dataclass(frozen=True)
class Box:
    """An upright box standing on the floor.

    Attributes:
        x: Centre x in world [m].
        y: Centre y in world [m].
        yaw: Rotation about world z [rad].
        half_x: Half length along its own x [m].
        half_y: Half length along its own y [m].
        height: Height [m].
    """

    x: float
    y: float
    yaw: float
    half_x: float
    half_y: float
    height: float

    def __post_init__(self) -> None:
        """Validate: finite numbers, positive sizes."""
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, int | float) and math.isfinite(v)):
                raise InvalidInputError(f"obstacle box {f.name} must be a finite number, got {v!r}")
        for name in ("half_x", "half_y", "height"):
            if getattr(self, name) <= 0.0:
                raise InvalidInputError(f"obstacle box {name} [m] must be > 0")

    def corners_xy(self) -> np.ndarray:
        """The footprint's four corners in world (4, 2) [m]."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        local = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * [self.half_x, self.half_y]
        return local @ np.array([[c, s], [-s, c]]) + [self.x, self.y]

    def as_dict(self) -> dict[str, float]:
        """JSON form."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class ObstacleCell:
    """What stands in the cell besides the bins and the brick (see the module docstring).

    Attributes:
        divider_height: Height of the divider wall between the bins [m]; 0: no divider.
        shelf_height: Height of the shelf's underside over bin 2 [m]; 0: no shelf.
        boxes: Boxes standing on the floor.
    """

    divider_height: float = 0.0
    shelf_height: float = 0.0
    boxes: tuple[Box, ...] = field(default=())

    def __post_init__(self) -> None:
        """Validate: heights finite and ≥ 0, at most :data:`MAX_BOXES` boxes."""
        for name in ("divider_height", "shelf_height"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0.0):
                raise InvalidInputError(f"{name} [m] must be a finite number >= 0, got {v!r}")
        object.__setattr__(self, "boxes", tuple(self.boxes))
        if len(self.boxes) > MAX_BOXES:
            raise InvalidInputError(
                f"an obstacle cell holds at most {MAX_BOXES} boxes, got {len(self.boxes)}"
            )

    @property
    def empty(self) -> bool:
        """True if nothing stands in the cell."""
        return self.divider_height == 0.0 and self.shelf_height == 0.0 and not self.boxes

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {
            "divider_height_m": self.divider_height,
            "shelf_height_m": self.shelf_height,
            "boxes": [b.as_dict() for b in self.boxes],
        }


__all__ = ["MAX_BOXES", "Box", "ObstacleCell"]
