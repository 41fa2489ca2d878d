"""Varied sweep parameters: parsing, reproducible per-seed draws, grids and binning."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as sps

from pickplace.errors import InvalidInputError, PickPlaceError
from pickplace.run.runner import CONTROL_RATE_RANGE_HZ
from pickplace.sim.vary import (
    PARAMETERS,
    ParameterDraw,
    VaryPlan,
    get_parameter,
    parse_spec,
    parse_vary,
)
from pickplace.sweep.bins import default_bin_count, success_by_bin, success_by_parameter
from pickplace.sweep.stats import wilson_interval

REQUIRED = ("brick_mass", "brick_size", "friction", "grip_force", "pose_noise", "speed")


# ---------------------------------------------------------------------------- names, parsing


def test_every_required_parameter_exists_with_a_unit() -> None:
    for name in (*REQUIRED, "control_rate"):
        p = PARAMETERS[name]
        assert p.unit and p.low < p.high and p.meaning
    assert PARAMETERS["brick_mass"].unit == "kg"
    assert PARAMETERS["grip_force"].unit == "N"
    assert PARAMETERS["pose_noise"].unit == "m"
    assert PARAMETERS["control_rate"].unit == "Hz"
    speed = PARAMETERS["speed"]
    assert speed.low > 0.0 and speed.high == 1.0  # a fraction in (0, 1]


def test_control_rate_bounds_are_the_runners() -> None:
    p = PARAMETERS["control_rate"]
    assert (p.low, p.high) == CONTROL_RATE_RANGE_HZ
    assert p.grid_only


def test_uniform_and_grid_syntax() -> None:
    u = parse_spec("brick_mass=0.2:12")
    assert (u.name, u.kind, u.low, u.high, u.values) == ("brick_mass", "uniform", 0.2, 12.0, ())
    g = parse_spec("control_rate=250,100,500")
    assert (g.kind, g.values, g.low, g.high) == ("grid", (250.0, 100.0, 500.0), 100.0, 500.0)
    one = parse_spec("friction=0.5")
    assert (one.kind, one.values) == ("grid", (0.5,))
    assert parse_spec("grip-force = 20:60").name == "grip_force"  # '-' reads as '_'
    assert u.describe() == "brick_mass ~ U(0.2, 12) kg"
    assert g.describe() == "control_rate in {250, 100, 500} Hz"


@pytest.mark.parametrize(
    "text", ["brick_mass=0.2:12", "control_rate=250,100", "pose_noise=0.0123456789:0.05"]
)
def test_a_spec_gives_back_its_flag(text: str) -> None:
    spec = parse_spec(text)
    assert spec.flag() == text
    assert parse_spec(spec.flag()) == spec


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("mass=1:2", "unknown parameter 'mass'"),
        ("brick_mass", "must be NAME=LOW:HIGH"),
        ("=1:2", "must be NAME=LOW:HIGH"),
        ("brick_mass=", "must be NAME=LOW:HIGH"),
        ("brick_mass=12:0.2", "LOW must be below HIGH"),
        ("brick_mass=2:2", "LOW must be below HIGH"),
        ("brick_mass=1:2:3", "must be NAME=LOW:HIGH"),
        ("brick_mass=1:2,3", "must be NAME=LOW:HIGH"),
        ("brick_mass=0:5", r"brick_mass \[kg\] must lie in \[0.01, 100\]"),
        ("friction=0.5,3", r"friction \[-\] must lie in \[0.05, 2\]"),
        ("speed=0:1", r"speed \[-\] must lie in \[0.1, 1\]"),
        ("speed=0.5:1.5", "got 1.5"),
        ("pose_noise=-0.01:0.02", "got -0.01"),
        ("speed=a:b", "'a' is not a number"),
        ("speed=nan:1", "finite"),
        ("grip_force=inf", "finite"),
        ("control_rate=100:500", "grid of values only"),
        ("friction=0.5,0.5", "must all differ"),
        ("friction=0.5,,1", "'' is not a number"),
    ],
)
def test_bad_specs_say_what_is_valid(text: str, expected: str) -> None:
    with pytest.raises(InvalidInputError, match=expected) as info:
        parse_spec(text)
    message = str(info.value)
    assert "\n" not in message
    assert isinstance(info.value, PickPlaceError)  # the CLI turns it into exit 2


def test_unknown_name_lists_every_name_with_unit_and_range() -> None:
    with pytest.raises(InvalidInputError) as info:
        get_parameter("weight")
    message = str(info.value)
    for p in PARAMETERS.values():
        assert f"{p.name} [{p.unit}] in [{p.low:g}, {p.high:g}]" in message


def test_a_parameter_given_twice_is_refused() -> None:
    with pytest.raises(InvalidInputError, match="brick_mass twice"):
        parse_vary(["brick_mass=1:2", "friction=1", "brick-mass=3:4"])


# ---------------------------------------------------------------------------- draws


def test_draws_are_reproducible_from_the_seed() -> None:
    plan = parse_vary(["brick_mass=0.2:12", "pose_noise=0:0.05", "control_rate=100,250"])
    again = parse_vary(["brick_mass=0.2:12", "pose_noise=0:0.05", "control_rate=100,250"])
    for seed in (0, 1, 17, 2**32 - 1):
        assert plan.draw(seed) == again.draw(seed)
    assert plan.draw(3) != plan.draw(4)


def test_adding_or_reordering_parameters_leaves_other_draws_unchanged() -> None:
    alone = parse_vary(["brick_mass=0.2:12"])
    more = parse_vary(["friction=0.2:1.5", "speed=0.2:1", "brick_mass=0.2:12", "grip_force=5"])
    for seed in range(200):
        assert alone.draw(seed).values["brick_mass"] == more.draw(seed).values["brick_mass"]
    swapped = parse_vary(["speed=0.2:1", "friction=0.2:1.5"])
    for seed in range(50):
        a, b = more.draw(seed), swapped.draw(seed)
        assert a.values["speed"] == b.values["speed"]
        assert a.values["friction"] == b.values["friction"]


def test_uniform_draws_are_uniform_and_independent() -> None:
    plan = parse_vary(["brick_mass=0.2:12", "friction=0.2:1.5"])
    draws = [plan.draw(s) for s in range(3000)]
    mass = np.array([d.values["brick_mass"] for d in draws])
    mu = np.array([d.values["friction"] for d in draws])
    assert mass.min() >= 0.2 and mass.max() <= 12.0
    assert sps.kstest(mass, sps.uniform(0.2, 11.8).cdf).pvalue > 1e-3
    assert sps.kstest(mu, sps.uniform(0.2, 1.3).cdf).pvalue > 1e-3
    assert abs(np.corrcoef(mass, mu)[0, 1]) < 4 / math.sqrt(len(draws))  # 4 sigma
    # ... and independent of the scenario's own stream default_rng(seed) (the brick pose).
    pose_u = np.array([np.random.default_rng(s).uniform() for s in range(3000)])
    assert abs(np.corrcoef(mass, pose_u)[0, 1]) < 4 / math.sqrt(len(draws))


def test_grid_combinations_cycle_with_the_seed() -> None:
    plan = parse_vary(["control_rate=100,250", "brick_mass=1:2", "speed=0.5,0.75,1"])
    assert plan.grid_size == 6
    combos = [
        (d.values["control_rate"], d.values["speed"], d.grid_index)
        for d in (plan.draw(s) for s in range(12))
    ]
    expected = [(100.0, 0.5), (100.0, 0.75), (100.0, 1.0), (250.0, 0.5), (250.0, 0.75)]
    expected.append((250.0, 1.0))
    assert [c[:2] for c in combos] == expected * 2  # last flag varies fastest
    assert [c[2] for c in combos] == [s % 6 for s in range(12)]
    # Any 6 consecutive seeds run every combination once.
    window = {(d.values["control_rate"], d.values["speed"]) for d in map(plan.draw, range(7, 13))}
    assert window == set(expected)


def test_pose_noise_moves_the_brick_by_its_magnitude_in_a_drawn_direction() -> None:
    plan = parse_vary(["pose_noise=0.01:0.03"])
    angles = []
    for seed in range(500):
        d = plan.draw(seed)
        offset = d.pose_offset_W
        assert offset is not None and offset[2] == 0.0
        assert np.linalg.norm(offset) == pytest.approx(d.values["pose_noise"], rel=1e-12)
        assert d.pose_noise_direction is not None
        angles.append(d.pose_noise_direction)
    assert sps.kstest(angles, sps.uniform(0, 2 * math.pi).cdf).pvalue > 1e-3
    grid = parse_vary(["pose_noise=0.02"]).draw(5)
    assert np.linalg.norm(grid.pose_offset_W) == pytest.approx(0.02)
    assert parse_vary(["friction=1"]).draw(5).pose_offset_W is None


def test_draw_records_are_json_ready_and_checked() -> None:
    d = parse_vary(["brick_mass=0.2:12", "pose_noise=0.01"]).draw(9)
    out = d.as_dict()
    assert out["seed"] == 9 and set(out["values"]) == {"brick_mass", "pose_noise"}
    assert math.hypot(*out["pose_offset_xy_m"]) == pytest.approx(0.01)
    assert "grid_index" in out
    with pytest.raises(InvalidInputError, match="must lie in"):
        ParameterDraw(0, {"brick_mass": 500.0})
    with pytest.raises(InvalidInputError, match="unknown parameter"):
        ParameterDraw(0, {"mass": 1.0})
    with pytest.raises(InvalidInputError, match="come together"):
        ParameterDraw(0, {"pose_noise": 0.01})
    with pytest.raises(InvalidInputError, match="non-negative integer"):
        VaryPlan().draw(-1)


def test_nothing_varied_draws_nothing() -> None:
    plan = parse_vary([])
    assert plan.grid_size == 1 and plan.describe() == "nothing varied but the seed"
    d = plan.draw(4)
    assert d.values == {} and d.grid_index is None and d.pose_offset_W is None


# ---------------------------------------------------------------------------- binning


def test_default_bin_count() -> None:
    assert [default_bin_count(n) for n in (0, 1, 4, 5, 40, 100, 200, 10_000)] == [
        1,
        1,
        2,
        3,
        7,
        10,
        10,
        10,
    ]


def test_uniform_bins_are_equal_width_over_the_spec_range() -> None:
    spec = parse_spec("brick_mass=2:10")
    values = [2.0, 3.99, 4.0, 5.5, 7.99, 8.0, 10.0]
    ok = [True, True, True, False, False, False, False]
    reasons = [None, None, None, "dropped", "dropped", "missed-grasp", "dropped"]
    out = success_by_bin(spec, values, ok, reasons, bins=4)
    assert [(b.low, b.high) for b in out] == [(2, 4), (4, 6), (6, 8), (8, 10)]
    assert [b.trials for b in out] == [2, 2, 1, 2]  # [lo, hi); 10 is in the closed last bin
    assert [b.successes for b in out] == [2, 1, 0, 0]
    assert out[3].failures == {"dropped": 1, "missed-grasp": 1}
    assert out[0].rate == wilson_interval(2, 2)
    assert out[1].center == 5.0 and out[1].label == "4–6"


def test_grid_bins_are_the_grid_values_in_order() -> None:
    spec = parse_spec("control_rate=250,100")
    out = success_by_bin(spec, [100.0, 250.0, 250.0], [True, False, True], [None, "nan", None])
    assert [(b.low, b.high, b.trials, b.successes) for b in out] == [
        (100.0, 100.0, 1, 1),
        (250.0, 250.0, 2, 1),
    ]
    assert out[1].label == "250" and out[1].failures == {"nan": 1}


def test_empty_bins_have_no_rate() -> None:
    spec = parse_spec("friction=0.1:1.1")
    out = success_by_bin(spec, [0.15, 0.2], [True, True], bins=5)
    assert [b.trials for b in out] == [2, 0, 0, 0, 0]
    assert out[1].rate is None and out[1].as_dict()["rate"] is None


def test_binning_refuses_values_outside_the_spec() -> None:
    with pytest.raises(InvalidInputError, match="outside"):
        success_by_bin(parse_spec("speed=0.5:1"), [0.4], [True])
    with pytest.raises(InvalidInputError, match="outside"):
        success_by_bin(parse_spec("speed=0.5,1"), [0.75], [True])
    with pytest.raises(InvalidInputError, match="one value, outcome and failure per trial"):
        success_by_bin(parse_spec("speed=0.5:1"), [0.6, 0.7], [True])
    with pytest.raises(InvalidInputError, match="bins"):
        success_by_bin(parse_spec("speed=0.5:1"), [0.6], [True], bins=0)


def test_success_by_parameter_matches_draws_to_trials_by_seed() -> None:
    plan = parse_vary(["brick_mass=0.2:12", "speed=0.5,1"])
    seeds = list(range(100, 140))
    draws = [plan.draw(s) for s in seeds]
    # A made-up outcome rule: heavy bricks fail. Trials are given in reverse seed order.
    trials = [
        {
            "seed": d.seed,
            "success": d.values["brick_mass"] < 8.0,
            "failure": None if d.values["brick_mass"] < 8.0 else "dropped",
        }
        for d in reversed(draws)
    ]
    out = success_by_parameter(plan, draws, trials, bins=4)
    mass = out["brick_mass"]
    assert sum(b.trials for b in mass) == 40
    assert mass[0].rate is not None and mass[0].rate.rate == 1.0
    assert mass[-1].rate is not None and mass[-1].rate.rate == 0.0
    assert mass[-1].failures == {"dropped": mass[-1].trials}
    assert [b.trials for b in out["speed"]] == [20, 20]
    with pytest.raises(InvalidInputError, match="no parameter draw"):
        success_by_parameter(plan, draws[:-1], trials)
