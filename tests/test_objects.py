"""The object's geometry (:mod:`pickplace.world.objects`): its support function and its
support patches, checked against points sampled on each primitive's surface (brute force),
and the questions every reader of the object's shape asks (width, rest height, footprint)."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import mujoco
import numpy as np
import pytest
from mink.lie import SE3, SO3

from pickplace.errors import SceneError
from pickplace.planning.candidates import GraspCandidate
from pickplace.planning.plan import PlanConfig, for_gripper
from pickplace.robot.calibration import MIN_PAD_CLEARANCE, pad_clearance
from pickplace.run.runner import RunRequest, run
from pickplace.sweep.trial import TrialSpec
from pickplace.world.objects import BUNDLED_OBJECTS, OBJECTS_DIR, ObjectGeom, ObjectGeometry
from pickplace.world.scene import Scene
from scripts import make_jar
from tests.conftest import CliRun

Cli = Callable[..., CliRun]

RNG_SEED = 23


def _directions(rng: np.random.Generator, n: int) -> np.ndarray:
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _surface_points(kind: str, size: np.ndarray, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` points on (or in) a primitive in its own frame, from its definition, not from
    any support formula: the brute-force reference."""
    if kind == "box":
        p = rng.uniform(-1.0, 1.0, size=(n, 3))
        axis = rng.integers(0, 3, size=n)
        p[np.arange(n), axis] = np.sign(p[np.arange(n), axis])  # on a face
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        return np.concatenate([p, corners]) * size
    if kind in ("sphere", "ellipsoid"):
        u = _directions(rng, n)
        axes = np.full(3, size[0]) if kind == "sphere" else size
        return u * axes
    r, h = float(size[0]), float(size[1])
    a = rng.uniform(0.0, 2 * math.pi, size=n)
    rim = np.stack([r * np.cos(a), r * np.sin(a), rng.uniform(-h, h, size=n)], axis=1)
    if kind == "cylinder":
        caps = rim.copy()
        caps[:, 2] = np.sign(rng.uniform(-1, 1, size=n)) * h
        caps[:, :2] *= np.sqrt(rng.uniform(0, 1, size=n))[:, None]
        edges = rim.copy()
        edges[:, 2] = np.sign(rng.uniform(-1, 1, size=n)) * h
        return np.concatenate([rim, caps, edges])
    assert kind == "capsule"
    u = _directions(rng, n)
    ends = u * r + np.where(u[:, 2:3] >= 0, 1.0, -1.0) * np.array([0.0, 0.0, h])
    return np.concatenate([rim, ends])


PRIMITIVES = [
    ("box", [0.05, 0.025, 0.02]),
    ("sphere", [0.03, 0.0, 0.0]),
    ("capsule", [0.02, 0.04, 0.0]),
    ("cylinder", [0.03, 0.05, 0.0]),
    ("ellipsoid", [0.04, 0.025, 0.015]),
]


def _geom(kind: str, size: list[float], rng: np.random.Generator) -> ObjectGeom:
    """One geom of ``kind``, turned and shifted at random in O."""
    R = SO3.from_rpy_radians(*rng.uniform(-math.pi, math.pi, size=3)).as_matrix()
    return ObjectGeom(kind, np.array(size), R, rng.uniform(-0.02, 0.02, size=3))


@pytest.mark.parametrize(("kind", "size"), PRIMITIVES, ids=[k for k, _ in PRIMITIVES])
def test_support_is_the_largest_projection_of_the_primitive_s_points(
    kind: str, size: list[float]
) -> None:
    rng = np.random.default_rng(RNG_SEED)
    g = _geom(kind, size, rng)
    shape = ObjectGeometry((g,), [0])
    points_O = _surface_points(kind, np.array(size), rng, 20000) @ g.R_Og.T + g.p_Og
    d = _directions(rng, 200)
    brute = (d @ points_O.T).max(axis=1)
    exact = shape.supports(d)
    # The sample never exceeds the support, and comes within the sampling's resolution of it.
    assert np.all(brute <= exact + 1e-12)
    assert np.max(exact - brute) < 2e-3 * max(size)
    # Along the geom's own axes the primitive's closed form is reached by a sampled point.
    for axis in g.R_Og.T:
        assert shape.support(axis) == pytest.approx((points_O @ axis).max(), abs=2e-3 * max(size))


@pytest.mark.parametrize(("kind", "size"), PRIMITIVES, ids=[k for k, _ in PRIMITIVES])
def test_the_support_patch_lies_on_the_support_plane(kind: str, size: list[float]) -> None:
    """Every corner of the patch's box, along the plane's directions, reaches the support:
    the patch is where flat pads pressing along -d touch."""
    rng = np.random.default_rng(RNG_SEED + 1)
    g = _geom(kind, size, rng)
    shape = ObjectGeometry((g,), [0])
    for d in _directions(rng, 50):
        c, h = shape.patch(d)
        assert float(c @ d) == pytest.approx(shape.support(d), abs=1e-9 + np.abs(d) @ h)


def test_a_box_s_patch_is_its_face_and_a_cylinder_s_side_a_line() -> None:
    box = ObjectGeometry(
        (ObjectGeom("box", np.array([0.05, 0.025, 0.02]), np.eye(3), np.zeros(3)),), [0]
    )
    c, h = box.patch([0.0, 1.0, 0.0])
    np.testing.assert_allclose(c, [0.0, 0.025, 0.0])
    np.testing.assert_allclose(h, [0.05, 0.0, 0.02])
    can = ObjectGeometry(
        (ObjectGeom("cylinder", np.array([0.03, 0.05, 0.0]), np.eye(3), np.zeros(3)),), [0]
    )
    d = np.array([math.cos(0.7), math.sin(0.7), 0.0])
    c, h = can.patch(d)
    np.testing.assert_allclose(c, 0.03 * d, atol=1e-12)
    np.testing.assert_allclose(h, [0.0, 0.0, 0.05], atol=1e-12)


def test_a_mesh_s_support_is_its_vertices_and_several_geoms_take_the_largest() -> None:
    rng = np.random.default_rng(RNG_SEED + 2)
    vertices = rng.normal(size=(40, 3)) * 0.03
    mesh = ObjectGeom("mesh", np.zeros(3), np.eye(3), np.array([0.0, 0.0, 0.01]), vertices)
    ball = ObjectGeom("sphere", np.array([0.02, 0.0, 0.0]), np.eye(3), np.array([0.05, 0.0, 0.0]))
    shape = ObjectGeometry((mesh, ball), [0, 1])
    ball_points = _surface_points("sphere", np.array([0.02]), rng, 20000) + ball.p_Og
    points = np.concatenate([vertices + mesh.p_Og, ball_points])
    d = _directions(rng, 200)
    brute = (d @ points.T).max(axis=1)
    assert np.all(brute <= shape.supports(d) + 1e-12)
    assert np.max(shape.supports(d) - brute) < 1e-4
    np.testing.assert_allclose(shape.half_extents, 0.5 * (points.max(0) - points.min(0)), atol=1e-4)


def _compiled(xml: str) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(xml)


def test_from_model_reads_the_collision_geoms_of_the_body_in_its_frame() -> None:
    model = _compiled(
        """<mujoco><worldbody><body name="o" pos="1 2 3"><freejoint/>
        <geom type="cylinder" size="0.03 0.05" pos="0 0 0.01"/>
        <geom type="sphere" size="0.5" contype="0" conaffinity="0"/>
        </body></worldbody></mujoco>"""
    )
    shape = ObjectGeometry.from_model(model, 1)
    assert [g.kind for g in shape.geoms] == ["cylinder"]  # the visual sphere is not grasped
    assert shape.rest_height == pytest.approx(0.04)  # its bottom 40 mm below O's origin
    X_OG = SE3.from_rotation(SO3.from_z_radians(0.4))
    assert shape.width_across(X_OG) == pytest.approx(0.06)
    np.testing.assert_allclose(shape.footprint_half(0.9), [0.03, 0.03])
    assert shape.min_footprint_half == pytest.approx(0.03)


def test_no_collision_geom_or_an_unsupported_one_is_refused_with_the_valid_types() -> None:
    visual = _compiled(
        """<mujoco><worldbody><body><freejoint/>
        <geom type="box" size="0.1 0.1 0.1" contype="0" conaffinity="0"/>
        </body></worldbody></mujoco>"""
    )
    with pytest.raises(SceneError, match=r"no collision geom; valid: .*cylinder"):
        ObjectGeometry.from_model(visual, 1)
    plane = ObjectGeom("plane", np.ones(3), np.eye(3), np.zeros(3))
    with pytest.raises(SceneError, match="type 'plane'; valid: box, sphere"):
        ObjectGeometry((plane,), [0])


def test_the_brick_keeps_its_box_formulas() -> None:
    half = np.array([0.05, 0.025, 0.02])
    brick = ObjectGeometry((ObjectGeom("box", half, np.eye(3), np.zeros(3)),), [0])
    assert brick.box_half_extents is half
    yaw = 0.3
    c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
    np.testing.assert_array_equal(
        brick.footprint_half(yaw), [c * half[0] + s * half[1], s * half[0] + c * half[1]]
    )
    X_OG = SE3.from_rotation(SO3.from_z_radians(yaw))
    y_O = X_OG.rotation().as_matrix()[:, 1]
    assert brick.width_across(X_OG) == float(2.0 * np.abs(y_O) @ half)
    # The general formulas agree with the box's.
    shifted = ObjectGeometry((ObjectGeom("box", half, np.eye(3), np.full(3, 1e-15)),), [0])
    assert shifted.box_half_extents is None
    np.testing.assert_allclose(shifted.footprint_half(yaw), brick.footprint_half(yaw), atol=1e-12)
    assert shifted.width_across(X_OG) == pytest.approx(brick.width_across(X_OG))


# ------------------------------------------------------------------ --object end to end

BAD_OBJECTS = {
    "missing.xml": (None, "is neither a bundled object nor a readable .xml file; valid: brick"),
    "broken.xml": ("<mujoco><worldbody><body", "cannot be read"),
    "fixed.xml": (
        '<mujoco><worldbody><body name="o"><geom type="box" size="0.02 0.02 0.02"/>'
        "</body></worldbody></mujoco>",
        "its body is not a free body; valid: an MJCF file whose worldbody holds one body",
    ),
    "two.xml": (
        '<mujoco><worldbody><body name="a"><freejoint/><geom size="0.02"/></body>'
        '<body name="b" pos="0 0 0.1"><freejoint/><geom size="0.02"/></body>'
        "</worldbody></mujoco>",
        "has 2 bodies",
    ),
    "ghost.xml": (
        '<mujoco><worldbody><body name="o"><freejoint/>'
        '<geom type="box" size="0.02 0.02 0.02" contype="0" conaffinity="0" mass="0.1"/>'
        "</body></worldbody></mujoco>",
        "no collision geom; valid: a body with at least one geom of type box",
    ),
    "drum.xml": (
        '<mujoco><worldbody><body name="o"><freejoint/>'
        '<geom type="cylinder" size="0.06 0.05" mass="0.3"/></body></worldbody></mujoco>',
        "the object (cylinder) is at least 120 mm across every horizontal direction",
    ),
    # A 40 mm tall block, a fin 8 mm thick and 200 mm long rising 100 mm from its top: the pads
    # close on the block across the fin, and at every tilt the hand between the fingers runs
    # into the fin (a post would let a tilted hand lean past it).
    "fin.xml": (
        '<mujoco><worldbody><body name="o"><freejoint/>'
        '<geom type="box" size="0.025 0.025 0.02" mass="0.2"/>'
        '<geom type="box" size="0.1 0.004 0.05" pos="0 0 0.07" mass="0.05"/>'
        "</body></worldbody></mujoco>",
        "is touched by more of the hand than its pads at every grasp",
    ),
}


@pytest.mark.parametrize("name", sorted(BAD_OBJECTS))
def test_a_bad_object_is_one_line_naming_what_is_wrong_exit_2(
    cli: Cli, tmp_path: Path, name: str
) -> None:
    text, expected = BAD_OBJECTS[name]
    if text is not None:
        (tmp_path / name).write_text(text)
    proc = cli("run", "--object", str(tmp_path / name))
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert lines[0].startswith("pickplace: error: --object: ")
    assert expected in lines[0]
    assert "valid:" in lines[0]
    assert proc.stdout == ""


def test_an_unknown_object_name_lists_the_bundled_ones(cli: Cli) -> None:
    proc = cli("plan", "--object", "teapot")
    assert proc.returncode == 2
    assert "valid: " + ", ".join(BUNDLED_OBJECTS) in proc.stderr


def test_the_help_names_every_bundled_object() -> None:
    from pickplace.cli import OBJECT_HELP

    assert all(name in OBJECT_HELP for name in BUNDLED_OBJECTS)


def test_a_sweep_refuses_a_bad_object_before_any_trial(cli: Cli, tmp_path: Path) -> None:
    proc = cli("sweep", "--trials", "1", "--workers", "1", "--object", str(tmp_path / "x.xml"))
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "--object: " in proc.stderr and proc.stdout == ""


def test_a_sweep_trial_s_rerun_command_names_its_object() -> None:
    spec = TrialSpec(scenario="pick-place-uniform", object="can")
    assert spec.request(7).object == "can"
    assert spec.rerun_command(7).endswith("--seed 7 --object can")


# Widths across any horizontal direction [m]: the can's and the ball's 60 mm; the jar, a
# 24-sided polygon around a 32 mm radius, between its faces' and its corners' distances.
WIDTHS = {
    "can": (0.06, 0.06),
    "ball": (0.06, 0.06),
    "jar": (0.064 * math.cos(math.pi / 24), 0.064),
}


@pytest.mark.parametrize("name", sorted(WIDTHS))
def test_the_object_rests_in_bin_1_and_is_grasped_across_its_width(name: str) -> None:
    from pickplace.run.runner import build_task

    scene, task = build_task(RunRequest(object=name))
    shape = scene.object
    assert shape.box_half_extents is None  # not the brick
    # Standing on bin 1's floor: its lowest point on the floor's top face.
    lowest = -float(shape.extent_W(task.X_WO_start, np.array([[0.0, 0.0, -1.0]]))[0])
    assert lowest == pytest.approx(scene.source_bin.floor_top_z, abs=1e-9)
    assert task.planning is not None and task.planning.feasible
    lo, hi = WIDTHS[name]
    grasps = object_grasps_of(scene)
    assert grasps
    opening = for_gripper(PlanConfig(), scene.robot.calibration).open_width
    for g in grasps:  # the opening is only as wide as the object plus the clearance a side
        assert lo - 1e-6 <= g.width <= hi + 1e-6  # a mesh is stored in float32
        clearance = pad_clearance(g.width, opening)
        assert clearance is not None
        if g.label.endswith(" mm a side"):  # the tight twin, where the whole clearance fits
            assert clearance > MIN_PAD_CLEARANCE
            assert g.open_width == pytest.approx(g.width + 2 * MIN_PAD_CLEARANCE)
        else:
            assert g.open_width == pytest.approx(g.width + 2 * clearance)
        assert shape.width_across(g.X_OG) == pytest.approx(g.width)


@pytest.mark.parametrize("name", ["can", "ball", "jar"])
def test_a_can_a_ball_and_a_jar_are_picked_and_placed(name: str) -> None:
    result = run(RunRequest(object=name))
    assert result.success, result.failure_text
    s = result.summary()
    assert s["place_error_m"] < 0.01


def test_a_user_s_object_of_several_geoms_is_picked_and_placed(tmp_path: Path) -> None:
    """A part nobody tuned for: a box with a dome (a sphere half sunk in its top) off its
    centre; the pads close where the object is widest along each direction (the box's faces)."""
    (tmp_path / "part.xml").write_text(
        '<mujoco><worldbody><body name="part"><freejoint/>'
        '<geom type="box" size="0.028 0.022 0.022" mass="0.08"/>'
        '<geom type="sphere" size="0.016" pos="0.008 0 0.02" mass="0.02"/>'
        "</body></worldbody></mujoco>"
    )
    result = run(RunRequest(object=str(tmp_path / "part.xml")))
    assert result.success, result.failure_text


def object_grasps_of(scene: Scene) -> list[GraspCandidate]:
    """The planner's grasp candidates of the scene's object."""
    from pickplace.planning.planner import PickPlacePlanner

    return PickPlacePlanner(scene, "qp").grasps()


def test_the_jar_file_is_what_its_script_writes_and_its_mesh_the_script_s_vertices() -> None:
    assert make_jar.main([]) == 0  # scenes/objects/jar.xml is make_jar.py's output
    model = mujoco.MjModel.from_xml_path(str(OBJECTS_DIR / "jar.xml"))
    shape = ObjectGeometry.from_model(model, 1)
    assert [g.kind for g in shape.geoms] == ["mesh"]
    points = np.array(make_jar.vertices())
    rng = np.random.default_rng(RNG_SEED + 3)
    d = _directions(rng, 100)
    # MuJoCo moves a mesh's vertices to its own frame: widths along any direction are kept.
    np.testing.assert_allclose(
        shape.supports(d) + shape.supports(-d),
        (d @ points.T).max(axis=1) - (d @ points.T).min(axis=1),
        atol=1e-6,
    )
    assert 2 * shape.half_extents[2] == pytest.approx(make_jar.HEIGHT, abs=1e-6)


def _placed(scene: Scene, X_WO: SE3) -> mujoco.MjData:
    """The scene's state with the object at ``X_WO`` at rest and the gripper at home."""
    data = mujoco.MjData(scene.model)
    mujoco.mj_resetDataKeyframe(scene.model, data, 0)
    a = scene.brick_qpos_adr
    data.qpos[a : a + 3] = X_WO.translation()
    data.qpos[a + 3 : a + 7] = X_WO.rotation().wxyz
    mujoco.mj_forward(scene.model, data)
    return data


@pytest.mark.parametrize("name", ["can", "ball"])
def test_the_verdict_asks_the_object_s_own_geometry(name: str) -> None:
    """Upright on bin 2's floor at its centre: placed. Moved until its side (not its centre)
    crosses a wall: not inside. Lying on its side: the can is tilted, the ball rests any
    way up."""
    from pickplace.run.runner import build_task
    from pickplace.sim.checks import SuccessCriteria
    from pickplace.sim.verdict import placement_problems

    scene, _ = build_task(RunRequest(object=name))
    bin_, criteria, shape = scene.target_bin, SuccessCriteria(), scene.object
    c = bin_.center_W
    up = SE3.from_translation(np.array([c[0], c[1], bin_.floor_top_z + shape.rest_height]))
    assert placement_problems(scene, _placed(scene, up), bin_, criteria, 0.0) == []
    # Its centre 1 mm less than its radius from the +x wall of bin 2's frame: it crosses it.
    x_B = bin_.X_WB.rotation().as_matrix()[:, 0]
    reach = float(bin_.inner_half_extents[0]) - shape.support(x_B) + 1e-3
    out = SE3.from_translation(up.translation() + reach * x_B)
    problems = placement_problems(scene, _placed(scene, out), bin_, criteria, 0.0)
    assert any("not inside" in p for p in problems)
    inside = SE3.from_translation(up.translation() + (reach - 2e-3) * x_B)
    assert placement_problems(scene, _placed(scene, inside), bin_, criteria, 0.0) == []
    side = SE3.from_rotation_and_translation(
        SO3.from_x_radians(math.pi / 2),
        np.array([c[0], c[1], bin_.floor_top_z + shape.support([0.0, 1.0, 0.0])]),
    )
    tilted = [p for p in placement_problems(scene, _placed(scene, side), bin_, criteria, 0.0)]
    assert (name == "can") == any("tilted" in p for p in tilted)
    assert not any("lowest" in p for p in tilted)  # on the floor either way
