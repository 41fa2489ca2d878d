"""Sweep statistics against published worked examples, scipy and their defining equations."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import stats as sps

from pickplace.errors import InvalidInputError
from pickplace.sweep.stats import (
    compare_paired,
    mcnemar_exact_p,
    newcombe_paired_interval,
    normal_quantile,
    paired_table,
    percentiles,
    success_rate,
    wilson_interval,
)

# ---------------------------------------------------------------------------- Wilson interval

# Newcombe, R. G. (1998a). Two-sided confidence intervals for the single proportion:
# comparison of seven methods. Stat. Med. 17, 857-872, Table II, method 3 (score interval
# without continuity correction), 95 %, printed to 4 decimals. The same examples appear in
# Altman et al. (2000), "Statistics with Confidence", 2nd ed., chapter 6.
NEWCOMBE_1998A = [
    (81, 263, 0.2553, 0.3662),
    (15, 148, 0.0624, 0.1605),
    (0, 20, 0.0000, 0.1611),
    (1, 29, 0.0061, 0.1718),
]

# R package binom 1.1 (Dorai-Raj), binom.confint(x, n, method="wilson"), 95 %, printed to
# 15-16 digits (as quoted in statsmodels' stats/tests/results/results_proportion.py).
R_BINOM_WILSON = [
    (18, 20, 0.6989663547715128, 0.972133518786232),
    (4, 20, 0.0806576625797981, 0.4160174322518935),
    (4, 200, 0.00780442641634947, 0.05028708690582643),
    (190, 200, 0.910421851861224, 0.972617354399236),
]


@pytest.mark.parametrize(("x", "n", "low", "high"), NEWCOMBE_1998A)
def test_wilson_matches_newcombe_1998_table(x: int, n: int, low: float, high: float) -> None:
    r = wilson_interval(x, n)
    assert r.low == pytest.approx(low, abs=5e-5)  # half a unit of the 4th printed decimal
    assert r.high == pytest.approx(high, abs=5e-5)


@pytest.mark.parametrize(("x", "n", "low", "high"), R_BINOM_WILSON)
def test_wilson_matches_r_binom_to_1e9(x: int, n: int, low: float, high: float) -> None:
    r = wilson_interval(x, n)
    assert r.low == pytest.approx(low, abs=1e-9)
    assert r.high == pytest.approx(high, abs=1e-9)


def test_wilson_interval_of_193_successes_in_200_is_about_93_to_98_percent() -> None:
    r = wilson_interval(193, 200)
    assert r.rate == 0.965
    assert 0.925 < r.low < 0.935 and 0.978 < r.high < 0.988  # "about 93-98 %"


@pytest.mark.parametrize("confidence", [0.5, 0.8, 0.9, 0.95, 0.99, 0.999])
@pytest.mark.parametrize("n", [1, 2, 7, 40, 200, 10_000])
def test_wilson_matches_scipy(n: int, confidence: float) -> None:
    for x in sorted({0, 1, n // 3, n // 2, n - 1, n}):
        ours = wilson_interval(x, n, confidence)
        ref = sps.binomtest(x, n).proportion_ci(confidence_level=confidence, method="wilson")
        assert ours.low == pytest.approx(ref.low, abs=1e-12)
        assert ours.high == pytest.approx(ref.high, abs=1e-12)


@pytest.mark.parametrize(("x", "n"), [(1, 3), (5, 40), (37, 40), (120, 200), (9999, 10_000)])
def test_wilson_limits_solve_the_score_equation(x: int, n: int) -> None:
    # The limits are the p with (x/n - p)^2 = z^2 p (1 - p) / n.
    for confidence in (0.9, 0.95, 0.99):
        z = normal_quantile(confidence)
        r = wilson_interval(x, n, confidence)
        for p in (r.low, r.high):
            assert (x / n - p) ** 2 == pytest.approx(z * z * p * (1 - p) / n, rel=1e-10)
        assert r.low < x / n < r.high


@pytest.mark.parametrize("n", [1, 5, 40, 1000])
def test_wilson_at_zero_and_all_successes(n: int) -> None:
    z2 = normal_quantile(0.95) ** 2
    none = wilson_interval(0, n)
    assert none.low == 0.0 and none.rate == 0.0
    assert none.high == pytest.approx(z2 / (n + z2), rel=1e-12)
    every = wilson_interval(n, n)
    assert every.high == 1.0 and every.rate == 1.0
    assert every.low == pytest.approx(n / (n + z2), rel=1e-12)


@pytest.mark.parametrize("n", [1, 6, 41, 500])
def test_wilson_is_symmetric_in_successes_and_failures(n: int) -> None:
    for x in range(0, n + 1, max(1, n // 10)):
        r, s = wilson_interval(x, n), wilson_interval(n - x, n)
        assert r.low == pytest.approx(1.0 - s.high, abs=1e-14)
        assert r.high == pytest.approx(1.0 - s.low, abs=1e-14)


def test_wilson_widens_with_confidence_and_narrows_with_trials() -> None:
    widths = [wilson_interval(30, 40, c) for c in (0.5, 0.9, 0.95, 0.99)]
    assert all(a.low > b.low and a.high < b.high for a, b in itertools.pairwise(widths))
    assert wilson_interval(300, 400).high - wilson_interval(300, 400).low < (
        widths[2].high - widths[2].low
    )


def test_wilson_coverage_is_near_nominal() -> None:
    # 95 % intervals cover the true rate in about 95 % of samples (here n = 60, p = 0.85).
    rng = np.random.default_rng(2024)
    xs = rng.binomial(60, 0.85, size=4000)
    covered = np.mean(
        [wilson_interval(int(x), 60).low <= 0.85 <= wilson_interval(int(x), 60).high for x in xs]
    )
    assert 0.93 <= covered <= 0.97


def test_normal_quantile_matches_scipy() -> None:
    assert normal_quantile(0.95) == pytest.approx(1.959963984540054, abs=1e-12)
    for c in (0.01, 0.5, 0.683, 0.9, 0.99, 0.999999):
        assert normal_quantile(c) == pytest.approx(sps.norm.ppf(0.5 + c / 2), rel=1e-12)


def test_success_rate_counts_outcomes() -> None:
    r = success_rate([True, False, True, True])
    assert (r.successes, r.trials, r.rate) == (3, 4, 0.75)
    assert r.as_dict()["method"] == "wilson"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((1, 0), "trials"),
        ((5, 4), "successes must be <= trials"),
        ((-1, 4), "successes"),
        ((1.5, 4), "successes"),
        ((True, 4), "successes"),
        ((1, 4, 1.0), "confidence"),
        ((1, 4, 0.0), "confidence"),
        ((1, 4, float("nan")), "confidence"),
        ((1, 4, "high"), "confidence"),
    ],
)
def test_wilson_refuses_bad_input(args: tuple, message: str) -> None:
    with pytest.raises(InvalidInputError, match=message):
        wilson_interval(*args)


def test_success_rate_of_nothing_is_refused() -> None:
    with pytest.raises(InvalidInputError, match="at least one outcome"):
        success_rate([])


# ---------------------------------------------------------------------------- McNemar


@pytest.mark.parametrize(
    ("b", "c"),
    [(0, 1), (1, 0), (3, 3), (12, 2), (2, 12), (6, 16), (0, 25), (40, 61), (1500, 1620)],
)
def test_mcnemar_matches_scipy_binomtest(b: int, c: int) -> None:
    ref = sps.binomtest(b, b + c, 0.5, alternative="two-sided").pvalue
    assert mcnemar_exact_p(b, c) == pytest.approx(ref, rel=1e-9, abs=1e-300)


def test_mcnemar_without_discordant_pairs_is_one() -> None:
    assert mcnemar_exact_p(0, 0) == 1.0


def test_mcnemar_small_case_by_hand() -> None:
    # b = 0, c = 5: 2 * (1/2)^5.
    assert mcnemar_exact_p(0, 5) == pytest.approx(2 / 32, rel=1e-14)
    assert mcnemar_exact_p(5, 0) == pytest.approx(2 / 32, rel=1e-14)


def test_mcnemar_refuses_negative_counts() -> None:
    with pytest.raises(InvalidInputError, match="a_only"):
        mcnemar_exact_p(-1, 3)


# ---------------------------------------------------------------------------- paired interval


def test_newcombe_paired_matches_newcombe_1998b_example() -> None:
    # Newcombe, R. G. (1998b). Improved confidence intervals for the difference between
    # binomial proportions based on paired data. Stat. Med. 17, 2635-2650: the example with
    # 36 pairs concordant positive, 12 and 2 discordant, 0 concordant negative; difference
    # +0.2000, method 10 interval +0.0569 to +0.3404 (4 decimals).
    low, high = newcombe_paired_interval(36, 12, 2, 0)
    assert low == pytest.approx(0.0569, abs=5e-5)
    assert high == pytest.approx(0.3404, abs=5e-5)


def test_newcombe_paired_matches_fagerland_2017_example() -> None:
    # Fagerland, Lydersen & Laake (2017), "Statistical Analysis of Contingency Tables",
    # chapter 8, complete response before and after consolidation therapy (Cavo et al. 2012):
    # table [[59, 6], [16, 80]], Newcombe square-and-add estimate -0.0621, 95 % CI -0.1186
    # to -0.0046.
    low, high = newcombe_paired_interval(59, 6, 16, 80)
    assert round((6 - 16) / 161, 4) == -0.0621
    assert low == pytest.approx(-0.1186, abs=5e-5)
    assert high == pytest.approx(-0.0046, abs=5e-5)


def test_newcombe_paired_reduces_to_independent_square_and_add_when_phi_is_zero() -> None:
    # ad - bc = 6*1 - 3*2 = 0 -> phi = 0: the limits are the unpaired square-and-add
    # (Newcombe 1998c, method 10) on the two margins 9/12 and 8/12.
    low, high = newcombe_paired_interval(6, 3, 2, 1)
    a, b = wilson_interval(9, 12), wilson_interval(8, 12)
    d = a.rate - b.rate
    assert low == pytest.approx(d - math.hypot(a.rate - a.low, b.high - b.rate), abs=1e-14)
    assert high == pytest.approx(d + math.hypot(a.high - a.rate, b.rate - b.low), abs=1e-14)


def test_positive_correlation_narrows_the_paired_interval() -> None:
    # Same margins (30/50 and 25/50), more concordance -> a narrower interval.
    loose = newcombe_paired_interval(15, 15, 10, 10)
    tight = newcombe_paired_interval(25, 5, 0, 20)
    assert tight[1] - tight[0] < loose[1] - loose[0]


def test_paired_interval_agrees_with_a_paired_bootstrap() -> None:
    # Brute force: resample seeds (pairs) with replacement; for a large sample the 2.5 and
    # 97.5 % quantiles of the resampled differences approach the method-10 limits.
    rng = np.random.default_rng(7)
    n = 2000
    u = rng.random(n)
    a = u < 0.80
    b = (u < 0.72) | ((u > 0.95) & (u < 0.99))  # correlated with a: 0.72 + 0.04 success
    cmp = compare_paired(a.tolist(), b.tolist())
    idx = rng.integers(0, n, size=(4000, n))
    diffs = a[idx].mean(axis=1) - b[idx].mean(axis=1)
    lo, hi = np.quantile(diffs, [0.025, 0.975])
    assert cmp.low == pytest.approx(lo, abs=0.003)
    assert cmp.high == pytest.approx(hi, abs=0.003)


def test_paired_interval_coverage_is_near_nominal() -> None:
    # Cell probabilities (both, a only, b only, neither); true difference 0.15 - 0.05 = 0.10.
    rng = np.random.default_rng(11)
    p = [0.70, 0.15, 0.05, 0.10]
    tables = rng.multinomial(100, p, size=3000)
    covered = [
        (lambda lo_hi: lo_hi[0] <= 0.10 <= lo_hi[1])(newcombe_paired_interval(*map(int, t)))
        for t in tables
    ]
    assert 0.93 <= float(np.mean(covered)) <= 0.97


def test_compare_paired_counts_and_rates() -> None:
    a = [True, True, False, True, False, True]
    b = [True, False, False, False, True, True]
    assert paired_table(a, b) == (2, 2, 1, 1)
    cmp = compare_paired(a, b)
    assert (cmp.both, cmp.a_only, cmp.b_only, cmp.neither, cmp.pairs) == (2, 2, 1, 1, 6)
    assert cmp.rate_a.rate == pytest.approx(4 / 6)
    assert cmp.rate_b.rate == pytest.approx(3 / 6)
    assert cmp.difference == pytest.approx(1 / 6)
    assert cmp.low < cmp.difference < cmp.high
    assert cmp.mcnemar_p == pytest.approx(sps.binomtest(1, 3).pvalue)
    d = cmp.as_dict()
    assert "Newcombe" in d["interval_method"] and "McNemar" in d["test_method"]


def test_compare_paired_is_antisymmetric() -> None:
    rng = np.random.default_rng(3)
    a = (rng.random(80) < 0.9).tolist()
    b = (rng.random(80) < 0.7).tolist()
    ab, ba = compare_paired(a, b), compare_paired(b, a)
    assert ab.difference == pytest.approx(-ba.difference)
    assert ab.low == pytest.approx(-ba.high, abs=1e-14)
    assert ab.high == pytest.approx(-ba.low, abs=1e-14)
    assert ab.mcnemar_p == ba.mcnemar_p


def test_identical_methods_give_an_interval_around_zero() -> None:
    # No discordant pairs: difference 0, McNemar p = 1, and still a non-degenerate interval
    # (a percentile bootstrap would collapse to [0, 0]).
    same = [True] * 45 + [False] * 5
    cmp = compare_paired(same, same)
    assert cmp.difference == 0.0 and cmp.mcnemar_p == 1.0
    assert cmp.low < 0.0 < cmp.high
    all_ok = compare_paired([True] * 10, [True] * 10)
    assert -1.0 <= all_ok.low < 0.0 < all_ok.high <= 1.0


def test_compare_paired_refuses_mismatched_vectors() -> None:
    with pytest.raises(InvalidInputError, match="one outcome of each method per seed"):
        compare_paired([True, False], [True])
    with pytest.raises(InvalidInputError, match="at least one seed"):
        compare_paired([], [])


# ---------------------------------------------------------------------------- percentiles


def test_percentiles_match_numpy_and_skip_missing_values() -> None:
    rng = np.random.default_rng(5)
    values = rng.lognormal(size=101)
    mixed: list[float | None] = [*values.tolist(), None, float("nan"), None]
    p = percentiles(mixed)
    assert p.count == 101
    assert p.p50 == pytest.approx(np.percentile(values, 50), rel=1e-14)
    assert p.p95 == pytest.approx(np.percentile(values, 95), rel=1e-14)
    assert p.max == values.max()


def test_percentiles_of_nothing_are_none() -> None:
    assert percentiles([None, float("nan")]).as_dict() == {
        "count": 0,
        "p50": None,
        "p95": None,
        "max": None,
    }


def test_percentiles_keep_infinity() -> None:
    p = percentiles([1.0, 2.0, math.inf, math.inf])
    assert p.max == math.inf and p.p95 == math.inf
    assert p.p50 == math.inf  # halfway between 2 and inf
    assert percentiles([3.0]).as_dict() == {"count": 1, "p50": 3.0, "p95": 3.0, "max": 3.0}
