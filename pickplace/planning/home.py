"""Choose a robot's home among IK candidates by planning the nominal pick-and-place from each."""

from __future__ import annotations

import dataclasses

import numpy as np

from pickplace.planning.planner import PickPlacePlanner, PlanningReport
from pickplace.world.placements import brick_on_floor, nominal_placement, target_placement
from pickplace.world.scene import Scene

HOME_CONTROLLER = "qp"
"""Controller whose pre-flight chooses among IK home candidates."""


def _rank(report: PlanningReport) -> tuple[int, int, float]:
    """Sort key of a home's nominal planning: feasible, earlier grasp, larger joint margin."""
    if report.chosen is None:
        return (1, len(report.candidates), 0.0)
    margin = report.candidates[report.chosen].preflight.min_joint_margin
    return (0, report.chosen, -margin)


def choose_home(scene: Scene, candidates: tuple[np.ndarray, ...]) -> np.ndarray:
    """The candidate home whose nominal pick-and-place plans best (see the module docstring).

    Each candidate is the scene's home in turn for the planner (:data:`HOME_CONTROLLER`'s
    pre-flight); the first of equally good ones (the candidates come best joint margin first)
    is returned. When none is feasible, the first candidate.
    """
    X_pick = brick_on_floor(scene, nominal_placement(scene), scene.source_bin.floor_top_z)
    X_place = brick_on_floor(scene, target_placement(scene), scene.target_bin.floor_top_z)
    best, best_rank = candidates[0], None
    for q in candidates:
        trial = dataclasses.replace(scene, robot=dataclasses.replace(scene.robot, q_home=q))
        report = PickPlacePlanner(trial, HOME_CONTROLLER, push=False).plan(X_pick, X_place)
        rank = _rank(report)
        if best_rank is None or rank < best_rank:
            best, best_rank = q, rank
    return best
