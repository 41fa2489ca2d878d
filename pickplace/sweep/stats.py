"""Statistics of a sweep: success rates with Wilson intervals, paired comparisons, percentiles.

Everything here is exact arithmetic on counts (no random numbers), so the same outcomes give
the same report. Only the standard library and numpy are used at run time; the tests check the
numbers against scipy and published worked examples.

- :func:`wilson_interval`: the Wilson score interval of a binomial proportion (Wilson 1927;
  Newcombe 1998a, method 3), at any confidence via the standard normal quantile.
- :func:`compare_paired`: two outcome vectors on the same seeds. The difference in success rate
  ``rate_a − rate_b`` gets Newcombe's square-and-add interval for paired data (Newcombe 1998b,
  method 10: Wilson limits of each rate combined with a continuity-corrected correlation φ̂);
  the test of "no difference" is McNemar's exact test, a two-sided binomial test of the
  discordant pairs against ½.
- :func:`percentiles`: p50, p95 and max of a metric, skipping None and NaN.

References:
    Wilson, E. B. (1927). Probable inference, the law of succession, and statistical inference.
    J. Am. Stat. Assoc. 22, 209–212.
    Newcombe, R. G. (1998a). Two-sided confidence intervals for the single proportion:
    comparison of seven methods. Stat. Med. 17, 857–872.
    Newcombe, R. G. (1998b). Improved confidence intervals for the difference between binomial
    proportions based on paired data. Stat. Med. 17, 2635–2650.
    McNemar, Q. (1947). Note on the sampling error of the difference between correlated
    proportions or percentages. Psychometrika 12, 153–157.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from statistics import NormalDist
from typing import Any

import numpy as np

from pickplace.errors import InvalidInputError

DEFAULT_CONFIDENCE = 0.95
PAIRED_METHOD = "Newcombe (1998) paired square-and-add, method 10 (Wilson limits, corrected phi)"
MCNEMAR_METHOD = "McNemar exact: two-sided binomial test of the discordant pairs against 1/2"


def normal_quantile(confidence: float) -> float:
    """The two-sided critical value z with P(|Z| ≤ z) = ``confidence`` for Z ~ N(0, 1).

    Args:
        confidence: Confidence level in (0, 1), e.g. 0.95 (z = 1.959964).

    Raises:
        InvalidInputError: ``confidence`` is not a number strictly between 0 and 1.
    """
    c = _confidence(confidence)
    return NormalDist().inv_cdf(0.5 + 0.5 * c)


def _confidence(confidence: float) -> float:
    try:
        c = float(confidence)
    except (TypeError, ValueError):
        raise InvalidInputError(
            f"confidence must be a number in (0, 1), e.g. 0.95; got {confidence!r}"
        ) from None
    if not 0.0 < c < 1.0:  # also refuses NaN
        raise InvalidInputError(f"confidence must be in (0, 1), e.g. 0.95; got {confidence!r}")
    return c


def _count(name: str, value: int, minimum: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InvalidInputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class RateInterval:
    """A success rate and its confidence interval.

    Attributes:
        successes: Number of successes.
        trials: Number of trials (≥ 1).
        rate: successes / trials.
        low: Lower limit of the interval.
        high: Upper limit of the interval.
        confidence: Confidence level of the interval, e.g. 0.95.
    """

    successes: int
    trials: int
    rate: float
    low: float
    high: float
    confidence: float

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable fields, plus the interval's method."""
        return {
            "successes": self.successes,
            "trials": self.trials,
            "rate": self.rate,
            "low": self.low,
            "high": self.high,
            "confidence": self.confidence,
            "method": "wilson",
        }


def wilson_interval(
    successes: int, trials: int, confidence: float = DEFAULT_CONFIDENCE
) -> RateInterval:
    """The Wilson score interval of a binomial proportion.

    The limits are the two proportions p at which the score statistic
    (p̂ − p) / √(p(1 − p)/n) equals ∓z: with p̂ = x/n,
    (p̂ + z²/2n ± z·√(p̂(1 − p̂)/n + z²/4n²)) / (1 + z²/n). They lie in [0, 1]; at x = 0 the
    lower limit is 0 and at x = n the upper limit is 1.

    Args:
        successes: Number of successes x, 0 ≤ x ≤ n.
        trials: Number of trials n ≥ 1.
        confidence: Confidence level in (0, 1).

    Raises:
        InvalidInputError: Counts that are not integers with 0 ≤ x ≤ n, n ≥ 1, or a
            confidence outside (0, 1).
    """
    n = _count("trials", trials, minimum=1)
    x = _count("successes", successes)
    if x > n:
        raise InvalidInputError(f"successes must be <= trials ({n}), got {x}")
    c = _confidence(confidence)
    z = normal_quantile(c)
    p = x / n
    z2n = z * z / n
    centre = (p + z2n / 2.0) / (1.0 + z2n)
    half = z * math.sqrt(p * (1.0 - p) / n + z2n / (4.0 * n)) / (1.0 + z2n)
    # Exact at the edges (the formula gives them up to rounding).
    low = 0.0 if x == 0 else max(0.0, centre - half)
    high = 1.0 if x == n else min(1.0, centre + half)
    return RateInterval(successes=x, trials=n, rate=p, low=low, high=high, confidence=c)


def success_rate(outcomes: Iterable[bool], confidence: float = DEFAULT_CONFIDENCE) -> RateInterval:
    """Success rate of ``outcomes`` (True = success) with its Wilson interval.

    Raises:
        InvalidInputError: No outcomes, or a confidence outside (0, 1).
    """
    values = [bool(o) for o in outcomes]
    if not values:
        raise InvalidInputError("a success rate needs at least one outcome, got none")
    return wilson_interval(sum(values), len(values), confidence)


def mcnemar_exact_p(a_only: int, b_only: int) -> float:
    """Two-sided p-value of McNemar's exact test from the discordant pairs.

    Under "A and B succeed equally often", each of the m = a_only + b_only discordant pairs is
    A's win with probability ½; the p-value is 2·P(X ≤ min(a_only, b_only)) for
    X ~ Binomial(m, ½), capped at 1 (1 when there are no discordant pairs). The binomial sum is
    taken in log space, so m may be large (relative error ~1e-12).

    Args:
        a_only: Pairs where A succeeded and B failed.
        b_only: Pairs where B succeeded and A failed.

    Raises:
        InvalidInputError: A count is not a non-negative integer.
    """
    b = _count("a_only", a_only)
    c = _count("b_only", b_only)
    m, k = b + c, min(b, c)
    if m == 0 or 2 * k == m:
        return 1.0
    # log C(m, j) for j = 0..k by a running sum of log((m - j + 1) / j).
    j = np.arange(1, k + 1, dtype=np.float64)
    log_comb = np.concatenate(([0.0], np.cumsum(np.log((m - j + 1.0) / j))))
    top = float(log_comb.max())
    log_tail = top + math.log(float(np.exp(log_comb - top).sum())) - m * math.log(2.0)
    return min(1.0, 2.0 * math.exp(log_tail))


@dataclass(frozen=True)
class PairedComparison:
    """Two methods A and B run on the same seeds.

    Attributes:
        pairs: Number of seeds n.
        both: Seeds where both succeeded.
        a_only: Seeds where only A succeeded.
        b_only: Seeds where only B succeeded.
        neither: Seeds where both failed.
        rate_a: A's success rate with its Wilson interval.
        rate_b: B's success rate with its Wilson interval.
        difference: rate_a − rate_b = (a_only − b_only) / n.
        low: Lower limit of the difference's interval (Newcombe method 10), ≥ −1.
        high: Upper limit of the difference's interval, ≤ 1.
        confidence: Confidence level of the intervals.
        mcnemar_p: Two-sided p-value of McNemar's exact test.
    """

    pairs: int
    both: int
    a_only: int
    b_only: int
    neither: int
    rate_a: RateInterval
    rate_b: RateInterval
    difference: float
    low: float
    high: float
    confidence: float
    mcnemar_p: float

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable fields, with the methods named."""
        return {
            "pairs": self.pairs,
            "both": self.both,
            "a_only": self.a_only,
            "b_only": self.b_only,
            "neither": self.neither,
            "rate_a": self.rate_a.as_dict(),
            "rate_b": self.rate_b.as_dict(),
            "difference": self.difference,
            "low": self.low,
            "high": self.high,
            "confidence": self.confidence,
            "interval_method": PAIRED_METHOD,
            "mcnemar_p": self.mcnemar_p,
            "test_method": MCNEMAR_METHOD,
        }


def paired_table(a: Sequence[bool], b: Sequence[bool]) -> tuple[int, int, int, int]:
    """Counts (both, a_only, b_only, neither) of two outcome vectors on the same seeds.

    Raises:
        InvalidInputError: The vectors differ in length or are empty.
    """
    if len(a) != len(b):
        raise InvalidInputError(
            f"paired outcomes need one outcome of each method per seed: got {len(a)} and {len(b)}"
        )
    if not a:
        raise InvalidInputError("a paired comparison needs at least one seed, got none")
    xa = np.asarray(a, dtype=bool)
    xb = np.asarray(b, dtype=bool)
    return (
        int(np.sum(xa & xb)),
        int(np.sum(xa & ~xb)),
        int(np.sum(~xa & xb)),
        int(np.sum(~xa & ~xb)),
    )


def newcombe_paired_interval(
    both: int, a_only: int, b_only: int, neither: int, confidence: float = DEFAULT_CONFIDENCE
) -> tuple[float, float]:
    """Newcombe's interval (1998b, method 10) for rate_a − rate_b on paired data.

    With n pairs, p_a = (both + a_only)/n, p_b = (both + b_only)/n, Wilson limits (l_a, u_a)
    and (l_b, u_b), and φ̂ the correlation of the two outcomes with Newcombe's correction
    (numerator ad − bc reduced by n/2 when above n/2, set to 0 between 0 and n/2; φ̂ = 0 when
    a margin is empty), the limits are
    Δ − √((p_a − l_a)² − 2φ̂(p_a − l_a)(u_b − p_b) + (u_b − p_b)²) and
    Δ + √((u_a − p_a)² − 2φ̂(u_a − p_a)(p_b − l_b) + (p_b − l_b)²), with Δ = p_a − p_b.

    Raises:
        InvalidInputError: Negative or non-integer counts, no pairs, or a bad confidence.
    """
    a = _count("both", both)
    b = _count("a_only", a_only)
    c = _count("b_only", b_only)
    d = _count("neither", neither)
    n = a + b + c + d
    if n == 0:
        raise InvalidInputError("a paired comparison needs at least one seed, got none")
    ra = wilson_interval(a + b, n, confidence)
    rb = wilson_interval(a + c, n, confidence)
    margins = (a + b) * (c + d) * (a + c) * (b + d)
    phi = 0.0
    if margins > 0:
        num = float(a * d - b * c)
        if num > n / 2.0:
            num -= n / 2.0
        elif num >= 0.0:
            num = 0.0
        phi = num / math.sqrt(float(margins))
    delta = ra.rate - rb.rate
    da_lo, da_hi = ra.rate - ra.low, ra.high - ra.rate
    db_lo, db_hi = rb.rate - rb.low, rb.high - rb.rate
    low = delta - math.sqrt(max(0.0, da_lo**2 - 2.0 * phi * da_lo * db_hi + db_hi**2))
    high = delta + math.sqrt(max(0.0, da_hi**2 - 2.0 * phi * da_hi * db_lo + db_lo**2))
    return max(-1.0, low), min(1.0, high)


def compare_paired(
    a: Sequence[bool], b: Sequence[bool], confidence: float = DEFAULT_CONFIDENCE
) -> PairedComparison:
    """Compare the outcomes of methods A and B on the same seeds (``a[i]``, ``b[i]``: seed i).

    Returns both rates with Wilson intervals, the difference rate_a − rate_b with Newcombe's
    paired interval (method 10) and McNemar's exact p-value.

    Raises:
        InvalidInputError: Vectors of different lengths, empty, or a bad confidence.
    """
    both, a_only, b_only, neither = paired_table(a, b)
    n = len(a)
    low, high = newcombe_paired_interval(both, a_only, b_only, neither, confidence)
    c = _confidence(confidence)
    return PairedComparison(
        pairs=n,
        both=both,
        a_only=a_only,
        b_only=b_only,
        neither=neither,
        rate_a=wilson_interval(both + a_only, n, c),
        rate_b=wilson_interval(both + b_only, n, c),
        difference=(a_only - b_only) / n,
        low=low,
        high=high,
        confidence=c,
        mcnemar_p=mcnemar_exact_p(a_only, b_only),
    )


@dataclass(frozen=True)
class Percentiles:
    """Summary of one metric over the trials that report it.

    Attributes:
        count: Number of finite values used (None and NaN are skipped).
        p50: Median, or None when there is no value.
        p95: 95th percentile, or None.
        max: Largest value, or None.
    """

    count: int
    p50: float | None
    p95: float | None
    max: float | None

    def as_dict(self) -> dict[str, Any]:
        """JSON-serialisable fields."""
        return {"count": self.count, "p50": self.p50, "p95": self.p95, "max": self.max}


def _quantile_sorted(x: np.ndarray, q: float) -> float:
    """Quantile ``q`` in [0, 1] of sorted ``x``: linear between order statistics (type 7)."""
    h = (len(x) - 1) * q
    lo = math.floor(h)
    hi = min(lo + 1, len(x) - 1)
    frac = h - lo
    if frac == 0.0 or x[lo] == x[hi]:  # also keeps ±inf without inf − inf = NaN
        return float(x[lo])
    return float(x[lo] + frac * (x[hi] - x[lo]))


def percentiles(values: Iterable[float | None]) -> Percentiles:
    """p50, p95 and max of ``values``, skipping None and NaN.

    Percentiles interpolate linearly between order statistics (numpy's default, Hyndman & Fan
    type 7). ±∞ counts as a value (e.g. a condition number that diverged at a singularity).
    """
    kept = [float(v) for v in values if v is not None and not math.isnan(float(v))]
    if not kept:
        return Percentiles(count=0, p50=None, p95=None, max=None)
    arr = np.sort(np.array(kept, dtype=np.float64))
    return Percentiles(
        count=len(kept),
        p50=_quantile_sorted(arr, 0.50),
        p95=_quantile_sorted(arr, 0.95),
        max=float(arr[-1]),
    )


__all__ = [
    "DEFAULT_CONFIDENCE",
    "MCNEMAR_METHOD",
    "PAIRED_METHOD",
    "PairedComparison",
    "Percentiles",
    "RateInterval",
    "compare_paired",
    "mcnemar_exact_p",
    "newcombe_paired_interval",
    "normal_quantile",
    "paired_table",
    "percentiles",
    "success_rate",
    "wilson_interval",
]
