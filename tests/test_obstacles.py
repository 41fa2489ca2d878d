"""Obstacle worlds: the cell's geometry, its composition with MjSpec, its world parameters."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from pickplace.errors import InvalidInputError
from pickplace.planning.preflight import Preflight
from pickplace.sim.loader import load_scene
from pickplace.sim.scenarios import CELL_DIVIDER_HEIGHT, SCENARIOS, obstacle_cell
from pickplace.sim.variation import apply_world
from pickplace.sim.vary import parse_spec, parse_vary
from pickplace.world.cell import Box, ObstacleCell
from pickplace.world.obstacles import (
    BOX_BASE_RADIUS,
    BOX_BIN_MARGIN,
    BOX_HOME_MARGIN,
    divider_box,
    draw_boxes,
    with_obstacles,
)
from pickplace.world.scene import Scene


def _names(model: mujoco.MjModel, kind: mujoco.mjtObj, count: int) -> list[str | None]:
    return [mujoco.mj_id2name(model, kind, i) for i in range(count)]


def test_obstacles_are_appended_world_geoms_and_every_id_is_kept(scene: Scene) -> None:
    cell = ObstacleCell(0.25, 0.85, draw_boxes(scene, np.random.default_rng(0), 3))
    new = with_obstacles(scene, cell)
    old = scene.model
    for kind, count in (
        (mujoco.mjtObj.mjOBJ_BODY, old.nbody),
        (mujoco.mjtObj.mjOBJ_GEOM, old.ngeom),
    ):
        assert _names(new.model, kind, count) == _names(old, kind, count)
    assert new.model.ngeom == old.ngeom + 1 + 3 + 3  # divider, shelf and 2 posts, 3 boxes
    added = range(old.ngeom, new.model.ngeom)
    assert all(new.is_world_geom(g) and not new.is_robot_geom(g) for g in added)
    # The robot, its home and its pad sensors are the scene's; one contact sensor per new body.
    np.testing.assert_array_equal(new.robot.q_home, scene.robot.q_home)
    np.testing.assert_array_equal(new.pad_force_sensor_adr, scene.pad_force_sensor_adr)
    assert len(new.robot_world_sensor_adr) == len(scene.robot_world_sensor_adr) + 7
    assert new.obstacles == cell and scene.obstacles is None
    assert with_obstacles(scene, ObstacleCell()) is scene


def test_the_divider_stands_between_the_bins_across_every_transfer(scene: Scene) -> None:
    """Its line lies on the bisector of the bins' azimuths, off both bins' footprints, and a
    point swung around the base from bin 1's centre to bin 2's at any radius it spans
    crosses it."""
    centre, yaw, half = divider_box(scene)
    base = scene.robot.p_W_base[:2]
    a1 = math.atan2(*(scene.source_bin.center_W[:2] - base)[::-1])
    a2 = math.atan2(*(scene.target_bin.center_W[:2] - base)[::-1])
    assert yaw == pytest.approx(0.5 * (a1 + a2))
    for r in np.linspace(0.3, 0.7, 5):  # bin 1 and bin 2 centres lie at 0.55 m
        d = np.array([math.cos(yaw), math.sin(yaw)])
        along = r - float((centre - base) @ d)
        assert abs(along) <= half[0]  # the radius r is within the wall's length


def test_random_boxes_keep_off_the_bins_and_the_base_and_follow_the_seed(scene: Scene) -> None:
    boxes = draw_boxes(scene, np.random.default_rng(7), 6)
    again = draw_boxes(scene, np.random.default_rng(7), 6)
    assert boxes == again and boxes != draw_boxes(scene, np.random.default_rng(8), 6)
    base = scene.robot.p_W_base[:2]
    from pickplace.control.kinematics import ArmKinematics

    kin = ArmKinematics(scene)
    kin.update(scene.robot.q_home)
    home = kin.p_WG()[:2]
    for b in boxes:
        corners = b.corners_xy()
        # The footprint's nearest point to the tool at home (a point of the box's rectangle).
        c, s = math.cos(b.yaw), math.sin(b.yaw)
        local = np.array([[c, s], [-s, c]]) @ (home - [b.x, b.y])
        assert (
            np.linalg.norm(np.maximum(np.abs(local) - [b.half_x, b.half_y], 0)) >= BOX_HOME_MARGIN
        )
        assert np.linalg.norm(corners - base, axis=1).min() >= BOX_BASE_RADIUS - 1e-9
        for bin_ in (scene.source_bin, scene.target_bin):
            local = bin_.to_bin_frame(np.column_stack([corners, np.zeros(4)]))[:, :2]
            outer = bin_.inner_half_extents + 0.01 + BOX_BIN_MARGIN  # walls 10 mm thick
            assert not np.all(np.abs(local) < outer, axis=1).any()


def test_the_preflight_sees_an_obstacle_where_the_home_hand_is(scene: Scene) -> None:
    """A box around the home tool: the pre-flight's clearance at home is negative there."""
    from pickplace.control.kinematics import ArmKinematics

    kin = ArmKinematics(scene)
    kin.update(scene.robot.q_home)
    x, y, z = kin.p_WG().tolist()
    box = Box(x, y, 0.0, 0.02, 0.02, z + 0.05)
    pf = Preflight(with_obstacles(scene, ObstacleCell(boxes=(box,))), "qp")
    X = kin.X_WG()
    kinds = pf.pair_kinds(X, X)
    d, contact = pf.clearance(scene.robot.q_home, 0.05, X, kinds, False)
    assert d < 0 and contact is not None and contact[1] == "cell_box1"


def test_world_parameters_parse_and_are_applied_before_planning(scene: Scene) -> None:
    with pytest.raises(InvalidInputError, match="whole numbers"):
        parse_spec("obstacle_boxes=1.5")
    with pytest.raises(InvalidInputError, match="grid"):
        parse_spec("obstacle_boxes=0:3")
    draw = parse_vary(["divider_height=0.25", "obstacle_boxes=2"]).draw(4)
    world = apply_world(scene, draw)
    assert world.obstacles is not None
    assert world.obstacles.divider_height == 0.25 and len(world.obstacles.boxes) == 2
    assert apply_world(scene, draw).obstacles == world.obstacles  # drawn from the seed
    # A varied parameter replaces the scenario's own.
    cell = obstacle_cell(scene, 4)
    mixed = apply_world(scene, parse_vary(["divider_height=0.2"]).draw(4), cell)
    assert mixed.obstacles is not None and mixed.obstacles.divider_height == 0.2
    assert mixed.obstacles.boxes == cell.boxes


def test_the_obstacle_scenario_draws_its_cell_from_the_seed() -> None:
    scene = load_scene()
    assert SCENARIOS["pick-place-obstacles"].world is obstacle_cell
    assert SCENARIOS["pick-place"].world is None
    cells = [obstacle_cell(scene, s) for s in range(40)]
    assert cells[3] == obstacle_cell(scene, 3)
    lo, hi = CELL_DIVIDER_HEIGHT
    assert all(lo <= c.divider_height <= hi for c in cells)
    assert any(c.shelf_height > 0 for c in cells) and any(c.shelf_height == 0 for c in cells)
    assert {len(c.boxes) for c in cells} == {0, 1, 2, 3}


def test_a_bad_cell_is_refused() -> None:
    with pytest.raises(InvalidInputError, match="divider_height"):
        ObstacleCell(divider_height=-0.1)
    with pytest.raises(InvalidInputError, match="at most"):
        ObstacleCell(boxes=(Box(1, 1, 0, 0.1, 0.1, 0.1),) * 7)
    with pytest.raises(InvalidInputError, match="half_x"):
        Box(1, 1, 0, 0.0, 0.1, 0.1)
