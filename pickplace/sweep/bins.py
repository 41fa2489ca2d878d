"""Success rate per bin of a varied parameter: one bin per grid value, or ⌈√n⌉ ≤ 10 equal bins
over a range, each with its Wilson interval and the failures in it."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pickplace.errors import InvalidInputError
from pickplace.sim.vary import ParameterDraw, VaryPlan, VarySpec
from pickplace.sweep.stats import DEFAULT_CONFIDENCE, RateInterval, wilson_interval

MAX_BINS = 10


@dataclass(frozen=True)
class BinStat:
    """Success rate of the trials whose value of one parameter falls in one bin.

    Attributes:
        parameter: Canonical parameter name.
        low: Lower edge of the bin (the grid value for a grid parameter).
        high: Upper edge of the bin (the grid value for a grid parameter).
        trials: Trials in the bin.
        successes: Successful trials in the bin.
        rate: Success rate with its Wilson interval, or None for an empty bin.
        failures: Failure reason → count, for the bin's failed trials.
    """

    parameter: str
    low: float
    high: float
    trials: int
    successes: int
    rate: RateInterval | None
    failures: Mapping[str, int]

    @property
    def center(self) -> float:
        """Middle of the bin (the grid value for a grid parameter)."""
        return 0.5 * (self.low + self.high)

    @property
    def label(self) -> str:
        """``0.2–1.4`` for a range, ``250`` for a grid value (unit not included)."""
        return f"{self.low:g}" if self.low == self.high else f"{self.low:.3g}–{self.high:.3g}"

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> BinStat:
        """The bin from its JSON form (:meth:`as_dict`, e.g. a report's ``by_parameter``)."""
        rate = None
        if d["rate"] is not None:
            rate = RateInterval(
                int(d["successes"]),
                int(d["trials"]),
                float(d["rate"]),
                float(d["rate_low"]),
                float(d["rate_high"]),
                float(d.get("confidence", DEFAULT_CONFIDENCE)),
            )
        return cls(
            str(d["parameter"]),
            float(d["low"]),
            float(d["high"]),
            int(d["trials"]),
            int(d["successes"]),
            rate,
            dict(d["failures"]),
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable fields."""
        return {
            "parameter": self.parameter,
            "low": self.low,
            "high": self.high,
            "trials": self.trials,
            "successes": self.successes,
            "rate": None if self.rate is None else self.rate.rate,
            "rate_low": None if self.rate is None else self.rate.low,
            "rate_high": None if self.rate is None else self.rate.high,
            "failures": dict(self.failures),
        }


def default_bin_count(trials: int) -> int:
    """⌈√trials⌉ equal-width bins, between 1 and :data:`MAX_BINS`."""
    return int(min(MAX_BINS, max(1, math.ceil(math.sqrt(max(trials, 0))))))


def success_by_bin(
    spec: VarySpec,
    values: Sequence[float],
    successes: Sequence[bool],
    failures: Sequence[str | None] | None = None,
    bins: int | None = None,
    confidence: float = DEFAULT_CONFIDENCE,
) -> list[BinStat]:
    """Success rate per bin of one varied parameter (bins as in the module docstring).

    Args:
        spec: The parameter's spec (its kind and range define the bins).
        values: The parameter's value in each trial.
        successes: Whether each trial succeeded.
        failures: Each trial's failure reason (None for a success), to count reasons per bin.
        bins: Number of equal-width bins of a uniform parameter; default
            :func:`default_bin_count` of the number of trials. Ignored for a grid.
        confidence: Confidence level of the Wilson intervals.

    Raises:
        InvalidInputError: Sequences of different lengths, a value outside the spec's range
            (or not in its grid), or a bin count outside [1, 100].
    """
    n = len(values)
    if len(successes) != n or (failures is not None and len(failures) != n):
        raise InvalidInputError(
            f"success_by_bin needs one value, outcome and failure per trial: got {n}, "
            f"{len(successes)}, {len(failures) if failures is not None else n}"
        )
    v = np.asarray(values, dtype=np.float64).reshape(n)
    if spec.kind == "grid":
        grid = np.array(sorted(spec.values))
        index = np.searchsorted(grid, v)
        inside = (index < len(grid)) & (grid[np.minimum(index, len(grid) - 1)] == v)
        edges = [(float(g), float(g)) for g in grid]
    else:
        count = default_bin_count(n) if bins is None else bins
        if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= 100:
            raise InvalidInputError(f"bins must be an integer in [1, 100], got {bins!r}")
        e = np.linspace(spec.low, spec.high, count + 1)
        index = np.clip(np.floor((v - spec.low) / (spec.high - spec.low) * count), 0, count - 1)
        index = index.astype(np.int64)
        inside = (v >= spec.low) & (v <= spec.high)
        edges = [(float(e[k]), float(e[k + 1])) for k in range(count)]
    if not np.all(inside):
        bad = float(v[~inside][0])
        raise InvalidInputError(
            f"{spec.name} value {bad:g} lies outside the sweep's {spec.describe()}"
        )
    out: list[BinStat] = []
    for k, (lo, hi) in enumerate(edges):
        members = [int(i) for i in np.flatnonzero(index == k)]
        ok = sum(bool(successes[i]) for i in members)
        reasons: dict[str, int] = {}
        if failures is not None:
            for i in members:
                if not successes[i]:
                    reason = str(failures[i])
                    reasons[reason] = reasons.get(reason, 0) + 1
        rate = wilson_interval(ok, len(members), confidence) if len(members) else None
        out.append(
            BinStat(spec.name, lo, hi, len(members), ok, rate, dict(sorted(reasons.items())))
        )
    return out


def success_by_parameter(
    plan: VaryPlan,
    draws: Sequence[ParameterDraw],
    trials: Sequence[Mapping[str, Any]],
    bins: int | None = None,
    confidence: float = DEFAULT_CONFIDENCE,
) -> dict[str, list[BinStat]]:
    """Success rate per bin of every varied parameter, matching draws to trials by seed.

    Args:
        plan: The sweep's varied parameters.
        draws: One draw per trial.
        trials: Trial summaries with at least ``seed``, ``success`` and ``failure``.
        bins: Bins per uniform parameter (see :func:`success_by_bin`).
        confidence: Confidence level of the Wilson intervals.

    Raises:
        InvalidInputError: A trial without a draw of its seed, or a draw without a value of a
            varied parameter.
    """
    by_seed = {d.seed: d for d in draws}
    missing = [int(t["seed"]) for t in trials if int(t["seed"]) not in by_seed]
    if missing:
        raise InvalidInputError(f"no parameter draw for the trials with seeds {missing[:10]}")
    matched = [by_seed[int(t["seed"])] for t in trials]
    successes = [bool(t["success"]) for t in trials]
    failures = [t.get("failure") for t in trials]
    out: dict[str, list[BinStat]] = {}
    for spec in plan.specs:
        values = []
        for d in matched:
            value = d.get(spec.name)
            if value is None:
                raise InvalidInputError(f"the draw of seed {d.seed} has no value of {spec.name}")
            values.append(value)
        out[spec.name] = success_by_bin(spec, values, successes, failures, bins, confidence)
    return out
