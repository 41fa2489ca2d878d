"""Varied parameters of a sweep: ``--vary NAME=LOW:HIGH`` (uniform) or ``--vary NAME=a,b,c`` (grid).

Every trial draws its parameters from its own seed, so a trial re-runs alone with the same
values (``pickplace run --seed SEED --vary ...``), whatever the sweep's first seed or order.

Parameters (canonical names, units, valid values; what a run does with the value):

================  =====  ===============  ====================================================
name              unit   valid            meaning
================  =====  ===============  ====================================================
``brick_mass``    kg     [0.01, 100]      mass of the brick; its inertia scales with it
``brick_size``    -      [0.5, 1.5]       scale factor of all three edge lengths of the brick
                                          (1 = the scene's brick); mass unchanged
``friction``      -      [0.05, 2]        sliding friction coefficient μ between the brick
                                          and the gripper pads
``grip_force``    N      [1, 200]         the gripper actuator's force limit (squeeze per jaw)
``pose_noise``    m      [0, 0.1]         after planning, the brick is moved by this distance
                                          in a horizontal direction drawn from the seed; the
                                          plan still aims at the unmoved pose
``speed``         -      [0.1, 1]         fraction of the planner's speed limits: speeds × s,
                                          accelerations × s², so every segment takes 1/s as
                                          long along the same path
``control_rate``  Hz     [100, 1000]      IK rate; grid only (a rate must divide the physics
                                          rate, e.g. 100, 125, 250, 500 Hz at 2 ms steps)
``attempts``      -      1 … 10           most attempts of a run (``--attempts``); grid of
                                          whole numbers only
``divider_height`` m     [0, 0.6]         a divider wall between the bins this high (0: none)
``shelf_height``  m      [0, 1.2]         a shelf over bin 2, its underside this high (0: none)
``obstacle_boxes`` -     {0, 1, …, 6}     this many boxes standing at random in the workspace;
                                          grid only; their sizes and places come from the
                                          parameter's own stream
================  =====  ===============  ====================================================

How values are drawn for the trial with seed ``s``:

- **Uniform** ``NAME=LOW:HIGH``: one value uniform in [LOW, HIGH] from the parameter's own
  random stream, ``SeedSequence(s, spawn_key=(STREAM_KEY, crc32(NAME)))``. Streams are keyed by
  name, so adding, removing or reordering other ``--vary`` flags never changes a parameter's
  draws, and they are independent of the scenario's own use of the seed (the brick pose of
  ``pick-place-random`` draws from ``default_rng(s)``).
- **Grid** ``NAME=a,b,c`` (one value or more, all different): the grid parameters form the
  cartesian product of their values, in the order of the flags with the last varying fastest
  (as :func:`itertools.product`); seed ``s`` takes combination ``s mod P`` (P = product of the
  grid lengths). Consecutive seeds cycle through every combination, so a sweep whose trial
  count is a multiple of P runs each combination equally often. Adding a grid parameter changes
  which combination a seed takes (uniform draws are unaffected).
- ``pose_noise`` also draws a direction θ uniform in [0, 2π) from its stream (after the
  magnitude); the brick moves by (r cos θ, r sin θ, 0) in world.

"Success rate per bin" (:func:`success_by_bin`): a grid parameter has one bin per grid value; a
uniform parameter has equal-width bins over its [LOW, HIGH] (the spec's range, not the data's,
so that two sweeps with the same spec share their bins), ⌈√n⌉ bins for n trials, at most 10,
each bin [lower edge, upper edge) and the last one closed.

The simulation applies the values (see the run request); :mod:`pickplace.sim.parameters`
defines them (importable without numpy), this module parses and draws them.
"""

from __future__ import annotations

import itertools
import math
import zlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from pickplace.errors import InvalidInputError
from pickplace.sim.parameters import PARAMETERS, Parameter, get_parameter, valid_parameters

# First word of every parameter stream's spawn key: "vary" in ASCII.
STREAM_KEY = 0x76617279

Kind = Literal["uniform", "grid"]


_SYNTAX = "NAME=LOW:HIGH (uniform) or NAME=a,b,c (grid), e.g. brick_mass=0.2:12"


@dataclass(frozen=True)
class VarySpec:
    """How one parameter varies over a sweep (one ``--vary`` flag).

    Attributes:
        parameter: The parameter.
        kind: ``"uniform"`` (drawn in [low, high]) or ``"grid"`` (cycling through ``values``).
        low: Lower end of the uniform range, or the smallest grid value.
        high: Upper end of the uniform range, or the largest grid value.
        values: Grid values in the order given (empty for uniform).
    """

    parameter: Parameter
    kind: Kind
    low: float
    high: float
    values: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        """Validate the range or grid against the parameter's bounds."""
        p = self.parameter
        if self.kind == "uniform":
            if self.values:
                raise InvalidInputError(f"--vary {p.name}: a uniform range takes no grid values")
            if p.grid_only:
                raise InvalidInputError(
                    f"--vary {p.name}={self.low:g}:{self.high:g}: {p.name} takes a grid of "
                    f"values only, {p.name}=a,b,c; {p.meaning}"
                )
            if not self.low < self.high:
                raise InvalidInputError(
                    f"--vary {p.name}={self.low:g}:{self.high:g}: LOW must be below HIGH "
                    f"(for one fixed value write {p.name}={self.low:g})"
                )
            ends: tuple[float, ...] = (self.low, self.high)
        elif self.kind == "grid":
            if not self.values:
                raise InvalidInputError(f"--vary {p.name}: a grid needs at least one value")
            if len(set(self.values)) != len(self.values):
                raise InvalidInputError(
                    f"--vary {p.name}: grid values must all differ, got "
                    f"{','.join(f'{v:g}' for v in self.values)}"
                )
            object.__setattr__(self, "values", tuple(float(v) for v in self.values))
            object.__setattr__(self, "low", min(self.values))
            object.__setattr__(self, "high", max(self.values))
            ends = self.values
        else:
            raise InvalidInputError(f"--vary kind must be 'uniform' or 'grid', got {self.kind!r}")
        for v in ends:
            if not (math.isfinite(v) and p.low <= v <= p.high):
                raise InvalidInputError(
                    f"--vary {p.name}: {p.name} [{p.unit}] must lie in [{p.low:g}, {p.high:g}] "
                    f"({p.meaning}); got {v:g}"
                )
        for v in self.values if p.whole else ():
            if not float(v).is_integer():
                raise InvalidInputError(
                    f"--vary {p.name}: {p.name} takes whole numbers in [{p.low:g}, {p.high:g}] "
                    f"({p.meaning}); got {v:g}"
                )

    @property
    def name(self) -> str:
        """The parameter's canonical name."""
        return self.parameter.name

    def describe(self) -> str:
        """``brick_mass ~ U(0.2, 12) kg`` or ``control_rate in {100, 250} Hz``."""
        unit = "" if self.parameter.unit == "-" else f" {self.parameter.unit}"
        if self.kind == "uniform":
            return f"{self.name} ~ U({self.low:g}, {self.high:g}){unit}"
        return f"{self.name} in {{{', '.join(f'{v:g}' for v in self.values)}}}{unit}"

    def flag(self) -> str:
        """The ``--vary`` value that gives this spec, e.g. ``brick_mass=0.2:12``."""
        if self.kind == "uniform":
            return f"{self.name}={_text(self.low)}:{_text(self.high)}"
        return f"{self.name}={','.join(_text(v) for v in self.values)}"

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable description."""
        out: dict[str, Any] = {
            "name": self.name,
            "unit": self.parameter.unit,
            "kind": self.kind,
            "low": self.low,
            "high": self.high,
        }
        if self.kind == "grid":
            out["values"] = list(self.values)
        return out


def _text(v: float) -> str:
    """Shortest text that reads back as exactly ``v``."""
    short = f"{v:g}"
    return short if float(short) == v else repr(v)


def _number(text: str, spec: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InvalidInputError(
            f"--vary '{spec}': '{text}' is not a number; write {_SYNTAX}"
        ) from None
    if not math.isfinite(v):
        raise InvalidInputError(f"--vary '{spec}': values must be finite, got '{text}'")
    return v


def parse_spec(text: str) -> VarySpec:
    """Parse one ``NAME=LOW:HIGH`` or ``NAME=a,b,c`` (a single value is a grid of one).

    Raises:
        InvalidInputError: Bad syntax, an unknown name, a value outside the parameter's
            range, LOW ≥ HIGH, repeated grid values or a range for a grid-only parameter;
            the message names the valid syntax, names, units and ranges.
    """
    name, sep, rest = text.partition("=")
    if not sep or not name.strip() or not rest.strip():
        raise InvalidInputError(
            f"--vary '{text}' must be {_SYNTAX}; valid names: {valid_parameters()}"
        )
    parameter = get_parameter(name)
    rest = rest.strip()
    if ":" in rest:
        parts = rest.split(":")
        if len(parts) != 2 or "," in rest:
            raise InvalidInputError(f"--vary '{text}' must be {_SYNTAX}")
        low, high = (_number(p, text) for p in parts)
        return VarySpec(parameter, "uniform", low, high)
    values = tuple(_number(p, text) for p in rest.split(","))
    return VarySpec(parameter, "grid", min(values), max(values), values)


@dataclass(frozen=True)
class ParameterDraw:
    """The parameter values of one trial.

    Attributes:
        seed: The trial's seed.
        values: Canonical name → value in the parameter's unit, for every varied parameter.
        grid_index: Index of the grid combination the trial took (None without a grid).
        pose_noise_direction: Direction θ [rad] of the brick's displacement in world
            (x axis = 0, counter-clockwise), when ``pose_noise`` is varied.
    """

    seed: int
    values: Mapping[str, float]
    grid_index: int | None = None
    pose_noise_direction: float | None = None

    def __post_init__(self) -> None:
        """Check names and values against :data:`PARAMETERS`; copy ``values``."""
        values = dict(self.values)
        for name, v in values.items():
            p = get_parameter(name)
            if name != p.name:
                raise InvalidInputError(f"parameter draw: use the canonical name '{p.name}'")
            if not (math.isfinite(v) and p.low <= v <= p.high):
                raise InvalidInputError(
                    f"parameter draw: {name} [{p.unit}] must lie in [{p.low:g}, {p.high:g}], "
                    f"got {v!r}"
                )
        if ("pose_noise" in values) != (self.pose_noise_direction is not None):
            raise InvalidInputError(
                "parameter draw: pose_noise and pose_noise_direction come together"
            )
        object.__setattr__(self, "values", values)

    def get(self, name: str, default: float | None = None) -> float | None:
        """The drawn value of ``name``, or ``default`` when it is not varied."""
        return self.values.get(name, default)

    @property
    def pose_offset_W(self) -> np.ndarray | None:
        """Displacement (dx, dy, 0) [m] of the brick in world after planning, or None."""
        if self.pose_noise_direction is None:
            return None
        r, t = self.values["pose_noise"], self.pose_noise_direction
        return np.array([r * math.cos(t), r * math.sin(t), 0.0])

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable fields (values by name; the pose offset when there is one)."""
        out: dict[str, Any] = {"seed": self.seed, "values": dict(self.values)}
        if self.grid_index is not None:
            out["grid_index"] = self.grid_index
        offset = self.pose_offset_W
        if offset is not None:
            out["pose_noise_direction_rad"] = self.pose_noise_direction
            out["pose_offset_xy_m"] = [float(offset[0]), float(offset[1])]
        return out


def parameter_stream(seed: int, name: str) -> np.random.Generator:
    """The random stream of parameter ``name`` for the trial with ``seed``."""
    key = zlib.crc32(name.encode("utf-8"))
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(STREAM_KEY, key)))


@dataclass(frozen=True)
class VaryPlan:
    """Every ``--vary`` of a sweep; draws each trial's parameters from its seed.

    Attributes:
        specs: One spec per varied parameter (names unique), in the order given.
    """

    specs: tuple[VarySpec, ...] = ()
    _grid: tuple[tuple[float, ...], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        """Refuse a parameter given twice; build the grid's combinations."""
        names = [s.name for s in self.specs]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise InvalidInputError(
                f"--vary: each parameter may be given once, got {', '.join(repeated)} twice"
            )
        object.__setattr__(self, "specs", tuple(self.specs))
        grids = [s.values for s in self.specs if s.kind == "grid"]
        object.__setattr__(self, "_grid", tuple(itertools.product(*grids)) if grids else ())

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the varied parameters, in the order given."""
        return tuple(s.name for s in self.specs)

    @property
    def grid_size(self) -> int:
        """Number of grid combinations P (1 without grid parameters)."""
        return max(1, len(self._grid))

    def spec(self, name: str) -> VarySpec:
        """The spec of the varied parameter ``name``.

        Raises:
            InvalidInputError: ``name`` is not varied; the message lists those that are.
        """
        for s in self.specs:
            if s.name == name:
                return s
        raise InvalidInputError(
            f"parameter '{name}' is not varied; varied: {', '.join(self.names) or '(none)'}"
        )

    def draw(self, seed: int) -> ParameterDraw:
        """The parameter values of the trial with ``seed`` (see the module docstring).

        Raises:
            InvalidInputError: ``seed`` is not a non-negative integer.
        """
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise InvalidInputError(f"seed must be a non-negative integer, got {seed!r}")
        seed = int(seed)
        grid_index = seed % len(self._grid) if self._grid else None
        combo = iter(self._grid[grid_index]) if grid_index is not None else iter(())
        values: dict[str, float] = {}
        direction: float | None = None
        for s in self.specs:
            rng = parameter_stream(seed, s.name)
            if s.kind == "uniform":
                values[s.name] = float(rng.uniform(s.low, s.high))
            else:
                values[s.name] = next(combo)
            if s.name == "pose_noise":
                direction = float(rng.uniform(0.0, 2.0 * math.pi))
        return ParameterDraw(seed, values, grid_index, direction)

    def describe(self) -> str:
        """One line: every spec, and the grid size when there is a grid."""
        if not self.specs:
            return "nothing varied but the seed"
        text = "; ".join(s.describe() for s in self.specs)
        return f"{text} ({self.grid_size} grid combinations)" if self._grid else text

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable description."""
        return {"parameters": [s.as_dict() for s in self.specs], "grid_size": self.grid_size}


def parse_vary(texts: Iterable[str]) -> VaryPlan:
    """Parse every ``--vary`` flag of a sweep.

    Raises:
        InvalidInputError: A bad flag (see :func:`parse_spec`) or a parameter given twice.
    """
    return VaryPlan(tuple(parse_spec(t) for t in texts))


# ---------------------------------------------------------------------------- binning


__all__ = [
    "PARAMETERS",
    "STREAM_KEY",
    "Parameter",
    "ParameterDraw",
    "VaryPlan",
    "VarySpec",
    "get_parameter",
    "parameter_stream",
    "parse_spec",
    "parse_vary",
    "valid_parameters",
]
