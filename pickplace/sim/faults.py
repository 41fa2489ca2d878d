"""Faults that scenarios inject to check that every failure gets its right verdict.

Each fault acts on the simulated world (:class:`~pickplace.sim.task.World`) at a chosen tick and
returns a text for the event log when it acts. None of them touches the verdict logic: they
change the world, and the checks must notice. A fault that must act at a moment of the task
reads it from the plan's phases, never from keyframe names.

To add a fault scenario: a class here with ``name`` and ``apply(world, tick)``, a
:class:`~pickplace.sim.scenarios.Scenario` row with its expected outcome, and its rows in the
scenario tables of README.md and docs/scenarios.md.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from pickplace.errors import InvalidInputError, SceneError
from pickplace.sim.task import World
from pickplace.sim.verdict import brick_touches_robot
from pickplace.world.scene import Scene


class GripperDisabled:
    """The gripper's actuators produce no force: the fingers never squeeze."""

    name = "gripper-disabled"

    def __init__(self, scene: Scene) -> None:
        self.actuators = scene.robot.gripper_actuator_ids.copy()

    def apply(self, world: World, tick: int) -> str | None:
        if tick != 0:
            return None
        world.model.actuator_gainprm[self.actuators, :] = 0.0
        world.model.actuator_biasprm[self.actuators, :] = 0.0
        return f"gain of the gripper's {len(self.actuators)} actuator(s) set to 0"


class BrickMoved:
    """After the plan was made, the brick is pushed 8 cm along world x, out of the fingers' way.

    8 cm exceeds half the brick's length (3.75 cm) plus a pad's half-width (1 to 1.1 cm for the
    bundled grippers), so the fingers close beside it.
    """

    name = "brick-moved"
    OFFSET_W = np.array([0.08, 0.0, 0.0])

    def __init__(self, scene: Scene) -> None:
        self.adr = scene.brick_qpos_adr

    def apply(self, world: World, tick: int) -> str | None:
        if tick != 0:
            return None
        world.data.qpos[self.adr : self.adr + 3] += self.OFFSET_W
        mujoco.mj_forward(world.model, world.data)
        return "brick moved by 0.08 m along x after planning"


class BrickShifted:
    """After the plan was made, the brick lies ``offset_W`` away from where it was planned for.

    A sweep's ``pose_noise`` (:mod:`pickplace.sim.vary`) draws the offset; the plan still aims at
    the planned pose, so the grasp meets the brick off-centre, or misses it.

    Args:
        scene: The scene.
        offset_W: Displacement (dx, dy, dz) of the brick in world [m].
    """

    name = "brick-shifted"

    def __init__(self, scene: Scene, offset_W: np.ndarray) -> None:
        self.adr = scene.brick_qpos_adr
        self.offset_W = np.array(offset_W, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(self.offset_W)):
            raise InvalidInputError(f"brick offset must be finite [m], got {self.offset_W}")

    def apply(self, world: World, tick: int) -> str | None:
        if tick != 0:
            return None
        world.data.qpos[self.adr : self.adr + 3] += self.offset_W
        mujoco.mj_forward(world.model, world.data)
        dx, dy = (1000.0 * self.offset_W[:2]).tolist()
        return f"brick moved by ({dx:.1f}, {dy:.1f}) mm in x, y after planning"


class HeavyBrick:
    """The brick weighs 30 kg: 294 N of weight against 2 pads × squeeze × μ 1 of friction (80 N
    for the iiwa's 40 N WSG-like gripper, 122 N for the strongest bundled one, the UR5e's)."""

    name = "heavy-brick"
    MASS = 30.0

    def __init__(self, scene: Scene) -> None:
        self.body = scene.brick_body_id

    def apply(self, world: World, tick: int) -> str | None:
        if tick != 0:
            return None
        m, d = world.model, world.data
        scale = self.MASS / m.body_mass[self.body]
        m.body_mass[self.body] *= scale
        m.body_inertia[self.body] *= scale
        # mj_setConst recomputes the model's constants from qpos0 and leaves qpos and qvel at
        # qpos0 and 0: keep the state the run is in.
        qpos, qvel = d.qpos.copy(), d.qvel.copy()
        mujoco.mj_setConst(m, d)
        d.qpos[:], d.qvel[:] = qpos, qvel
        mujoco.mj_forward(m, d)
        return f"brick mass set to {self.MASS:.0f} kg"


class Knock:
    """Blows that knock the carried brick down out of the grip, from halfway through the first
    motion of the transport phase.

    A blow is an impulse: the brick's downward speed jumps by ``FACTOR`` times the speed the
    pads' friction would take out of it over its own height (the farthest it can slide and
    still be between the pads), ``sqrt(2 · a · h)`` with ``a = μ · 2 · squeeze / m − g`` (the
    pads' friction coefficient, the gripper's measured squeeze per jaw, the brick's mass and
    height). Grips hold differently (slide jaws let the brick slip; a linkage carries it with
    the hand, the arm taking the blow), so the blow comes again each tick while the brick
    still touches the robot and no longer slides out (down, relative to the tool, at less
    than half a blow's speed), at most ``MAX_BLOWS`` times: it leaves the pads at well under
    one blow's speed, and falls from where it was carried.
    """

    name = "knock"
    FACTOR = 0.8
    MAX_BLOWS = 20

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.dof = scene.brick_dof_adr
        self.site = scene.robot.tool_site_id
        self._t_hit: float | None = None
        self._blows = 0
        self.dv = 0.0

    def _blow_speed(self, world: World) -> float:
        """The blow's speed [m/s] from the world as it is (a varied mass or friction)."""
        m, robot = world.model, self.scene.robot
        mu = robot.pad_friction(m)
        mass = float(m.body_mass[self.scene.brick_body_id])
        decel = mu * 2.0 * robot.measured_squeeze_force / mass + float(m.opt.gravity[2])
        height = 2.0 * float(self.scene.brick_half_extents[2])
        return self.FACTOR * math.sqrt(2.0 * max(decel, 0.0) * height)

    def apply(self, world: World, tick: int) -> str | None:
        if self._blows >= self.MAX_BLOWS:
            return None
        if self._t_hit is None:
            phases = world.plan.phases
            if phases is None:
                return None  # nothing is carried, nothing to knock
            start = phases.transport[0]
            self._t_hit = 0.5 * (start + world.plan.trajectory.next_keyframe_time(start))
        if tick * world.dt < self._t_hit:
            return None
        if self._blows:
            if not brick_touches_robot(self.scene, world.data):
                self._blows = self.MAX_BLOWS  # knocked out: no more blows
                return None
            v = np.zeros(6)
            m, d = world.model, world.data
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, self.site, v, 0)
            if d.qvel[self.dof + 2] - v[5] < -0.5 * self.dv:
                return None  # still sliding out from the last blow
        if not self._blows:
            self.dv = self._blow_speed(world)
        self._blows += 1
        world.data.qvel[self.dof + 2] -= self.dv
        if self._blows == 1:
            return f"blow on the brick: {self.dv:.2f} m/s downward, again each tick it is held"
        return None


class Obstacle:
    """After planning, a 0.12 m box appears in the transfer path: the plan runs into it.

    The scene parks a mocap body ``obstacle`` far out of the way; at tick 0 this fault moves
    it onto the planned tool path: the point of the middle half of the plan's transport phase
    farthest from the rest of the tool's path (so only the transfer runs into it). The checks
    must report the robot's collision at the tick of first contact.
    """

    name = "obstacle"
    BODY = "obstacle"

    def __init__(self, scene: Scene) -> None:
        m = scene.model
        self.body = int(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, self.BODY))
        if self.body < 0 or m.body_mocapid[self.body] < 0:
            raise SceneError(f"the obstacle fault needs a mocap body '{self.BODY}' in the scene")
        self.mocap = int(m.body_mocapid[self.body])

    def apply(self, world: World, tick: int) -> str | None:
        if tick != 0 or world.plan.phases is None:
            return None
        start, end = world.plan.phases.transport
        traj = world.plan.trajectory
        quarter = 0.25 * (end - start)
        inside = np.array(
            [traj.sample(t)[0][4:] for t in np.linspace(start + quarter, end - quarter, 41)]
        )
        others = [t for t in np.linspace(0.0, traj.end_time, 400) if not start <= t <= end]
        outside = np.array([traj.sample(t)[0][4:] for t in others])
        clearance = np.linalg.norm(inside[:, None] - outside[None], axis=2).min(axis=1)
        p_W = inside[int(np.argmax(clearance))]
        m, d = world.model, world.data
        d.mocap_pos[self.mocap] = p_W
        mujoco.mj_forward(m, d)
        x, y, z = p_W.tolist()
        return f"a box appeared at ({x:.2f}, {y:.2f}, {z:.2f}) m, in the planned transfer path"


class InjectNaN:
    """A NaN written into the brick's velocity at t = 1 s (a corrupted state)."""

    name = "nan"
    TIME = 1.0

    def __init__(self, scene: Scene) -> None:
        self.dof = scene.brick_dof_adr

    def apply(self, world: World, tick: int) -> str | None:
        if tick != round(self.TIME / world.dt):
            return None
        world.data.qvel[self.dof] = np.nan
        return "NaN written into the brick's velocity"
