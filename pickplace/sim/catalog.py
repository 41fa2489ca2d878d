"""What each named scenario is: its name, its one-line summary and its documented outcomes.

Importable without numpy, MuJoCo or the planner, so that ``pickplace scenarios`` answers at once;
:mod:`pickplace.sim.scenarios` joins each row to the builder that makes its task.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field


@dataclass(frozen=True)
class ScenarioInfo:
    """A named scenario, without its builder.

    Attributes:
        name: Registry key.
        summary: One line shown by ``pickplace scenarios``.
        expected: ``"success"`` or the failure reason the scenario is designed to produce
            with the default controller (``qp``).
        expected_with: Documented outcomes with other controllers, where they differ or are
            the point of the scenario (e.g. ``{"pinv": "limit-violated"}``).
        uses_brick: Whether ``--brick`` applies.
        random: Whether the seed changes the task.
    """

    name: str
    summary: str
    expected: str = "success"
    expected_with: Mapping[str, str] = field(default_factory=dict)
    uses_brick: bool = True
    random: bool = False

    def outcomes(self) -> dict[str, str]:
        """Documented outcome per controller: ``qp`` and every one in ``expected_with``."""
        return {"qp": self.expected, **self.expected_with}


CATALOG: dict[str, ScenarioInfo] = {
    s.name: s
    for s in (
        ScenarioInfo("pick-place", "nominal pick from bin 1's centre, place at bin 2's centre"),
        ScenarioInfo(
            "pick-place-random",
            "brick x, y, yaw drawn from the seed over bin 1's floor (drawn again until the "
            "planner finds a feasible plan)",
            random=True,
        ),
        ScenarioInfo(
            "pick-place-uniform",
            "brick x, y, yaw drawn from the seed uniformly over bin 1's valid poses and never "
            "drawn again: measures how much of the bin is picked (success where a candidate is "
            "feasible; else no-feasible-plan, naming the best candidate's problem)",
            random=True,
        ),
        ScenarioInfo(
            "pick-place-obstacles",
            "nominal pick and place in a cell drawn from the seed: a divider wall between the "
            "bins of random height, maybe a shelf over bin 2, a few random boxes (success "
            "where a plan is feasible, around them in C-space where the Cartesian one "
            "collides; else no-feasible-plan, naming what blocks)",
            random=True,
        ),
        ScenarioInfo(
            "singular-reach",
            "tool pulled along a straight line past full arm stretch "
            "and back (qp stays within limits, pinv does not)",
            expected_with={"pinv": "limit-violated", "dls": "limit-violated"},
            uses_brick=False,
        ),
        ScenarioInfo(
            "fault-gripper-disabled",
            "the gripper's actuators have no force -> missed-grasp",
            expected="missed-grasp",
        ),
        ScenarioInfo(
            "fault-brick-moved",
            "the brick is moved 8 cm after planning -> missed-grasp",
            expected="missed-grasp",
        ),
        ScenarioInfo(
            "fault-heavy-brick",
            "the brick weighs 30 kg, more than friction at the pads holds -> dropped",
            expected="dropped",
        ),
        ScenarioInfo(
            "fault-knock",
            "an impulse knocks the brick out of the gripper mid-transport -> dropped",
            expected="dropped",
        ),
        ScenarioInfo(
            "fault-unreachable",
            "place target 1.6 m away, outside the arm's reach, executed without the "
            "pre-flight -> ik-failed",
            expected="ik-failed",
        ),
        ScenarioInfo(
            "fault-nan",
            "a NaN is injected into the brick's velocity mid-run -> nan",
            expected="nan",
        ),
        ScenarioInfo(
            "fault-obstacle",
            "after planning, a box appears in the transfer path -> ik-failed (qp keeps clear "
            "of it), collision without the collision limit",
            expected="ik-failed",
            expected_with={"qp-no-collision": "collision", "pinv": "collision", "dls": "collision"},
        ),
    )
}


__all__ = ["CATALOG", "ScenarioInfo"]
