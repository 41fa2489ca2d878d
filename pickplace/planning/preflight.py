"""The kinematic pre-flight: a plan executed by the run's own controller, before any physics.

The IK never reads the simulated state: it integrates its commanded joint positions open loop
(:mod:`pickplace.sim.loop`). Running the same controller over the whole plan kinematically therefore
predicts the commanded joint path, up to the coarser rate the pre-flight runs at
(:attr:`PreflightConfig.rate_hz`). At every pre-flight tick it checks, in this order:

1. the IK: a solution exists, and the commanded tool stays within
   :attr:`PreflightConfig.tracking_tolerance` of the plan;
2. the joints: each one at least :attr:`PreflightConfig.joint_margin` inside its range, and no
   commanded speed above its limit;
3. the Jacobian: σmin at least :attr:`PreflightConfig.min_singular_value`;
4. collisions: every robot geom (arm links, palm, fingers at their commanded width, or at the
   grasped brick's width from the pick, where they close onto it, until they let go of it) and
   the brick while it is held, against every world geom (bins, floor, obstacles), at least
   :attr:`PreflightConfig.clearance` apart. MuJoCo's own collision detection (``mj_collision``
   with geom margins) runs on a kinematic copy of the scene's model; the robot never collides
   with the brick there (the grasp is the physics' job). The plan leaves the brick's start
   and reaches its goal along straight vertical moves (the lift, the place's descent): there
   the held brick ignores the geoms it lies beside at that pose, those within the clearance
   plus :attr:`PreflightConfig.tracking_tolerance` of it (the floor under it, a wall beside
   it), since moving straight up or down it comes no nearer to them than by the IK's drift
   off the plan, which the tracking check bounds. The reported minimum clearance still
   counts the walls it lies beside there (not what it rests against: within the clearance,
   the floor under it). In the transport between them every pair counts.

The first problem found ends the pre-flight; a plan without problems is feasible, and its
margins over the whole plan are reported.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import mujoco
import numpy as np
from mink.lie import SE3

from pickplace.control.controllers import (
    DiffIKController,
    IKResult,
    IKStatus,
    make_controller,
    without_collision_limit,
)
from pickplace.errors import PlanError, require_positive
from pickplace.planning.plan import Plan, grasp_width
from pickplace.planning.trajectory import PoseTrajectory
from pickplace.signals import stop_point
from pickplace.world.scene import Scene

# Contact bits of the kinematic copy: the robot touches the world, the brick touches the
# world, and neither touches the other (nor the robot itself).
_WORLD_CONTYPE, _WORLD_CONAFFINITY = 1, 1 | 2
_ROBOT_CONTYPE, _ROBOT_CONAFFINITY = 2, 0
_BRICK_CONTYPE, _BRICK_CONAFFINITY = 4, 1
# A brick geom within this distance of a world geom rests on it [m].
_SUPPORT_DISTANCE = 1e-3
# The longest plan [s] a pre-flight takes: an hour of simulated time. A pre-flight keeps
# (8 n + 2) numbers per tick for n joints (0.46 kB for 7), 72,000 ticks at 20 Hz: 33 MB.
MAX_PLAN_DURATION_S = 3600.0
# Within a C-space motion the controller runs at this rate between pre-flight ticks (the
# loop's default control rate) [Hz].
FINE_RATE_HZ = 100.0
# A stop request is looked for every this many pre-flight ticks (a few ms of work).
_STOP_POINT_TICKS = 16


@dataclass(frozen=True)
class PreflightConfig:
    """Rate and thresholds of the pre-flight.

    Attributes:
        rate_hz: Rate at which the controller is run and every check made [Hz]. 20 Hz predicts
            the same problems as the 100 Hz control rate on the measured plans at a fifth of
            the cost (see ``docs/physics-notes.md``, "Planning failures on bin 1").
        clearance: Smallest distance allowed between a robot geom (or the held brick) and the
            world [m]: a few mm more than the position actuators' tracking error.
        detection_distance: Distances up to this are measured, for the reported minimum
            clearance [m]; farther geoms count as "at least this far".
        joint_margin: Smallest distance of a joint from its range's ends [rad]: twice the QP's
            own limit margin (0.005 rad), so a joint the QP pins at a limit is flagged.
        tracking_tolerance: Largest distance of the commanded tool from the plan [m]: half the
            run's ik-failed limit (20 mm); a tracking IK lags the plan by well under 1 mm.
        speed_ratio_tolerance: Commanded joint speeds may exceed their limits by this
            fraction (the QP's solver tolerance) [-].
        min_singular_value: Smallest σ of the tool Jacobian: a tenth of the nominal
            pick-and-place's 0.22; below it the arm is near a singularity.
        midpoint_feedforward: Give the controller the plan's velocity at the middle of each
            pre-flight tick instead of its start. The loop integrates at its control rate, where
            the difference is negligible; at the pre-flight's coarser rate the start's velocity
            leaves a lag of ½ a dt² (6 mm at 5 m/s² and 20 Hz) that the loop does not have, the
            midpoint's only O(dt³). False reproduces the loop exactly when both run at one rate.
    """

    rate_hz: float = 20.0
    clearance: float = 0.005
    detection_distance: float = 0.03
    joint_margin: float = 0.01
    tracking_tolerance: float = 0.01
    speed_ratio_tolerance: float = 1e-6
    min_singular_value: float = 0.02
    midpoint_feedforward: bool = True

    def __post_init__(self) -> None:
        """Validate every field (all must be finite numbers > 0, and the detection distance
        beyond the clearance plus the tracking tolerance: what the brick lies beside)."""
        for name in (
            "rate_hz",
            "clearance",
            "detection_distance",
            "joint_margin",
            "tracking_tolerance",
            "speed_ratio_tolerance",
            "min_singular_value",
        ):
            require_positive(f"pre-flight {name}", getattr(self, name))
        beside = self.clearance + self.tracking_tolerance
        if not self.detection_distance > beside:
            raise PlanError(
                f"pre-flight detection_distance must exceed clearance + tracking_tolerance "
                f"({beside} m), got {self.detection_distance} m"
            )


@dataclass(frozen=True)
class Problem:
    """The first thing that makes a plan infeasible.

    Attributes:
        t: Plan time [s].
        kind: ``"ik"``, ``"joint-limit"``, ``"speed-limit"``, ``"singularity"`` or
            ``"collision"``.
        text: One line for a person: what, where, how much.
        point_W: Where it happened in world [m]: the contact point, or the limited joint's
            anchor, or the tool.
        lagging: An ``"ik"`` problem of the commanded tool falling behind the plan while the
            IK's step was held by a limit (status ``limited``): a path driven faster than the
            robot's joints allow.
    """

    t: float
    kind: str
    text: str
    point_W: tuple[float, float, float]
    lagging: bool = False

    def as_dict(self) -> dict[str, object]:
        """JSON form."""
        return {"t": self.t, "kind": self.kind, "text": self.text, "point": list(self.point_W)}


@dataclass(frozen=True)
class PreflightResult:
    """What the pre-flight found.

    Attributes:
        problem: The first problem, or None if the plan is feasible.
        t_checked: Plan time up to which the plan was checked [s].
        min_clearance: Smallest robot-world (and held-brick-world) distance seen [m], capped at
            the detection distance.
        min_joint_margin: Smallest distance of a joint from its range's ends [rad].
        peak_speed_ratio: Largest |q̇ᵢ| / limitᵢ [-].
        min_singular_value: Smallest σ of the tool Jacobian [-].
        times: Plan times of the pre-flight ticks [s], shape (n,).
        q: Commanded joint positions at those times [rad], shape (n, joints): the joint path.
    """

    problem: Problem | None
    t_checked: float
    min_clearance: float
    min_joint_margin: float
    peak_speed_ratio: float
    min_singular_value: float
    times: np.ndarray = field(repr=False)
    q: np.ndarray = field(repr=False)

    @property
    def feasible(self) -> bool:
        """True if no problem was found."""
        return self.problem is None

    def margins(self) -> dict[str, float]:
        """The margins in JSON form."""
        return {
            "min_clearance_m": self.min_clearance,
            "min_joint_margin_rad": self.min_joint_margin,
            "peak_speed_ratio": self.peak_speed_ratio,
            "min_singular_value": self.min_singular_value,
        }


# Of two problems at the same time, the one earlier in this list is reported.
_KIND_ORDER = ("ik", "joint-limit", "speed-limit", "singularity", "collision")


class Preflight:
    """Runs plans through a controller and the scene's geometry without physics.

    Args:
        scene: The scene (its model is copied, never changed).
        controller: Name of the run's controller (``qp``, ``qp-no-collision``, ``pinv`` or
            ``dls``); ``qp`` runs without its collision limit, as ``qp-no-collision``.
        config: Rate and thresholds.
    """

    def __init__(
        self, scene: Scene, controller: str, config: PreflightConfig | None = None
    ) -> None:
        self.scene = scene
        self.config = config or PreflightConfig()
        self.dt = 1.0 / self.config.rate_hz
        # The run's controller without its collision limit: at the pre-flight's rate a tick
        # moves the tool up to 50 mm (20 mm in the path sweep), beyond the limit's detection
        # distance and its linearisation, and it brakes the tool beside walls that the path
        # clears by more than the clearance (the planner then refused feasible candidates);
        # a plan kept this far from the world never meets the limit's 2 mm at the control
        # rate (docs/planning.md, "The collision limit").
        self.controller = make_controller(without_collision_limit(controller), scene, self.dt)
        self.model = collision_model(scene, self.config.detection_distance)
        self.data = mujoco.MjData(self.model)
        self._names = scene.robot.arm_joint_names
        ng = self.model.ngeom
        self._world = np.array([scene.is_world_geom(g) for g in range(ng)])
        self._robot = np.array([scene.is_robot_geom(g) for g in range(ng)])
        self._gripper_qpos_adr = scene.gripper_qpos_adr
        self._width = math.nan  # the last width loaded, and its gripper joint positions
        self._gripper_qpos = scene.robot.qpos_for_width(0.0)
        self._fine: DiffIKController | None = None  # made for the first C-space motion

    def run(
        self,
        plan: Plan,
        X_WO_start: SE3,
        X_WO_goal: SE3 | None,
        stop_at_problem: bool = True,
        q_start: np.ndarray | None = None,
    ) -> PreflightResult:
        """Pre-flight ``plan`` from the home posture, or from ``q_start``.

        The IK and collision checks run tick by tick (a problem there can end the run early);
        the joint, speed and σmin checks run on the whole joint path afterwards, vectorised;
        the first problem in time is the plan's.

        Args:
            plan: The plan (its phases say when the brick is held).
            X_WO_start: Brick pose before it is grasped.
            X_WO_goal: Brick pose after it is released (None: it stays at the start).
            stop_at_problem: Stop at the first problem (else check the whole plan).
            q_start: Commanded arm configuration the plan starts from [rad] (a replan at run
                time starts where the arm stopped); None: the robot's home posture. The plan's
                first keyframe should be its tool pose.

        Raises:
            PlanError: ``q_start`` is not one finite angle per arm joint.
        """
        cfg, sc, dt = self.config, self.scene, self.dt
        q0 = start_configuration(sc, q_start)
        traj, phases = plan.trajectory, plan.phases
        X_GO = plan.X_OG.inverse() if plan.X_OG is not None else None
        width_held = grasp_width(plan, sc)
        held = (phases.grip_closed, phases.release) if phases and X_GO is not None else None
        transport = phases.transport if phases is not None else (-math.inf, math.inf)
        # From the pick on, the brick is between the fingers: they close onto it, no further.
        on_brick = (phases.approach[1], phases.release) if held is not None and phases else None
        X_WO_end = X_WO_goal if X_WO_goal is not None else X_WO_start
        pair_kind = self.pair_kinds(X_WO_start, X_WO_end)
        command, sample = self.controller.command, traj.sample
        # A C-space motion's joint path steers the controller's null space (posture).
        joints = traj.joint_sample if traj.has_joint_segments else None
        following = False
        check_plan_duration(traj.end_time)
        n = math.floor(traj.end_time / dt + 1e-9) + 1
        times = np.arange(n) * dt
        nq = len(sc.robot.q_home)
        q_path, qdot_path, J_path = np.zeros((n, nq)), np.zeros((n, nq)), np.zeros((n, 6, nq))
        clear_path = np.full(n, cfg.detection_distance)
        tracking_sq = cfg.tracking_tolerance**2
        midpoint = cfg.midpoint_feedforward
        q = q0
        found: Problem | None = None  # the first IK or collision problem
        end = n
        half_dt = 0.5 * dt
        for i in range(n):
            if i % _STOP_POINT_TICKS == 0:
                stop_point()
            t = float(times[i])
            x, V, width = sample(t)
            if midpoint:  # the plan's velocity at the middle of the tick
                V = sample(t + half_dt)[1]
            if joints is not None:
                js = joints(t + half_dt if midpoint else t)
                if js is not None or following:
                    self.controller.follow_joints(*(js if js is not None else (None, None)))
                following = js is not None
            res = command(q, x, V)
            q_path[i], qdot_path[i], J_path[i] = q, res.qdot, res.J_WG
            is_held = held is not None and held[0] <= t < held[1]
            # Held in the lift or the place's descent, not the transport between them.
            vertical = is_held and not transport[0] <= t <= transport[1]
            X_WO = X_WO_start if held is None or t < held[0] else X_WO_end
            if is_held and X_GO is not None:
                X_WO = SE3(res.x_WG) @ X_GO
            if on_brick is not None and on_brick[0] <= t < on_brick[1]:
                width = max(width, width_held)
            clearance, contact, nearest = self._closest(
                q, width, X_WO, pair_kind, is_held, vertical
            )
            clear_path[i] = nearest
            if found is None:
                found = self._tick_problem(t, x, res, clearance, contact, tracking_sq)
                if found is not None and stop_at_problem:
                    end = i + 1
                    break
            # A C-space motion is integrated at the loop's rate within the tick.
            q = self._fine_steps(q, t, traj) if following else q + res.qdot * dt
        if following:
            self.controller.follow_joints(None)
        problems = [
            p for p in (found, *self._path_problems(times, q_path, qdot_path, J_path, end)) if p
        ]
        problem = min(problems, key=lambda p: (p.t, _KIND_ORDER.index(p.kind)), default=None)
        if problem is not None and stop_at_problem:
            end = min(end, round(problem.t / dt) + 1)
        q_all = q_path[:end]
        margin = np.minimum(q_all - sc.robot.q_min, sc.robot.q_max - q_all)
        ratio = np.abs(qdot_path[:end]) / sc.robot.v_max
        sigma = np.linalg.svd(J_path[:end], compute_uv=False)[:, -1]
        return PreflightResult(
            problem=problem,
            t_checked=float(times[end - 1]),
            min_clearance=float(clear_path[:end].min()),
            min_joint_margin=float(margin.min()),
            peak_speed_ratio=float(ratio.max()),
            min_singular_value=float(sigma.min()),
            times=times[:end],
            q=q_all,
        )

    def _fine_steps(self, q: np.ndarray, t: float, traj: PoseTrajectory) -> np.ndarray:
        """``q`` after one pre-flight tick from ``t`` along a C-space motion, the controller
        run at :data:`FINE_RATE_HZ` within it (midpoint feed-forward, the joint path followed):
        a joint path turns the tool faster than the Cartesian paths the pre-flight's own rate
        was measured on, and integrating it in 20 Hz steps lags by more than the loop does."""
        fine = self._fine
        if fine is None:
            fine = self._fine = make_controller(
                self.controller.name, self.scene, 1.0 / FINE_RATE_HZ
            )
        steps = max(1, round(self.dt * FINE_RATE_HZ))
        h = self.dt / steps
        for k in range(steps):
            ts = t + k * h
            js = traj.joint_sample(ts + 0.5 * h)
            fine.follow_joints(*(js if js is not None else (None, None)))
            x = traj.sample(ts)[0]
            V = traj.sample(ts + 0.5 * h)[1]
            q = q + fine.command(q, x, V).qdot * h
        return q

    def _tick_problem(
        self,
        t: float,
        x_plan: np.ndarray,
        res: IKResult,
        clearance: float,
        contact: tuple[str, str, tuple[float, float, float]] | None,
        tracking_sq: float,
    ) -> Problem | None:
        """The IK or collision problem at one tick, if any."""
        cfg = self.config
        px, py, pz = res.x_WG[4:].tolist()
        if res.status is IKStatus.NO_SOLUTION:
            return Problem(t, "ik", "the IK finds no solution", (px, py, pz))
        tx, ty, tz = x_plan[4:].tolist()
        err_sq = (tx - px) ** 2 + (ty - py) ** 2 + (tz - pz) ** 2
        if err_sq > tracking_sq:
            text = (
                f"the commanded tool falls {math.sqrt(err_sq) * 1000:.0f} mm behind the plan "
                f"(limit {cfg.tracking_tolerance * 1000:.0f} mm; status {res.status.value}): "
                "unreachable or too fast"
            )
            if self.scene.robot.a_max is None:
                text += (
                    " (the robot's description gives no accel_limits, so motions start at full "
                    "speed: give them, or lower --speed)"
                )
            return Problem(t, "ik", text, (px, py, pz), res.status is IKStatus.LIMITED)
        if contact is not None and clearance < cfg.clearance:
            a, b, pos = contact
            text = (
                f"{a} comes within {clearance * 1000:.1f} mm of {b} (clearance "
                f"{cfg.clearance * 1000:.0f} mm)"
            )
            return Problem(t, "collision", text, pos)
        return None

    def _path_problems(
        self,
        times: np.ndarray,
        q: np.ndarray,
        qdot: np.ndarray,
        J: np.ndarray,
        end: int,
    ) -> list[Problem]:
        """The first joint-limit, speed-limit and singularity problems on ticks [0, end)."""
        cfg, sc = self.config, self.scene
        q, qdot = q[:end], qdot[:end]
        out: list[Problem] = []
        below, above = q - sc.robot.q_min, sc.robot.q_max - q
        margin = np.minimum(below, above)
        bad = np.flatnonzero(margin.min(axis=1) < cfg.joint_margin)
        if bad.size:
            k = int(bad[0])
            j = int(np.argmin(margin[k]))
            side, limit = (
                ("lower", sc.robot.q_min[j])
                if below[k, j] < above[k, j]
                else ("upper", sc.robot.q_max[j])
            )
            text = (
                f"{self._names[j]} at {q[k, j]:.3f} rad is {margin[k, j]:.3f} rad from its "
                f"{side} limit {limit:.3f} rad (margin {cfg.joint_margin} rad)"
            )
            out.append(Problem(float(times[k]), "joint-limit", text, self._anchor_at(q[k], j)))
        ratio = np.abs(qdot) / sc.robot.v_max
        bad = np.flatnonzero(ratio.max(axis=1) > 1.0 + cfg.speed_ratio_tolerance)
        if bad.size:
            k = int(bad[0])
            j = int(np.argmax(ratio[k]))
            text = (
                f"{self._names[j]} commanded at {abs(qdot[k, j]):.2f} rad/s, "
                f"{ratio[k, j]:.2f}x its limit {sc.robot.v_max[j]:.2f} rad/s"
            )
            out.append(Problem(float(times[k]), "speed-limit", text, self._anchor_at(q[k], j)))
        sigma = np.linalg.svd(J[:end], compute_uv=False)[:, -1]
        bad = np.flatnonzero(sigma < cfg.min_singular_value)
        if bad.size:
            k = int(bad[0])
            text = (
                f"the tool Jacobian's smallest singular value is {sigma[k]:.4f} (below "
                f"{cfg.min_singular_value}): near a singularity"
            )
            self._load_arm(q[k])
            out.append(Problem(float(times[k]), "singularity", text, self._tool_point()))
        return out

    # ------------------------------------------------------------------ geometry

    def _anchor_at(self, q: np.ndarray, j: int) -> tuple[float, float, float]:
        """World position of arm joint ``j``'s anchor with the arm at ``q``."""
        self._load_arm(q)
        p = self.data.xanchor[self.scene.robot.arm_joint_ids[j]]
        return (float(p[0]), float(p[1]), float(p[2]))

    def observe_world(self, mocap_pos: np.ndarray, mocap_quat: np.ndarray) -> None:
        """Place the collision model's mocap bodies (an obstacle a fault moved) where the
        simulation has them: the kinematics of every later check (:meth:`run`,
        :meth:`clearance`) puts them there.

        Args:
            mocap_pos: The simulation's ``data.mocap_pos`` (nmocap, 3) [m].
            mocap_quat: Its ``data.mocap_quat`` (nmocap, 4), wxyz.
        """
        self.data.mocap_pos[:] = mocap_pos
        self.data.mocap_quat[:] = mocap_quat

    def _load_arm(self, q: np.ndarray) -> None:
        """Arm at ``q``: kinematics only."""
        self.data.qpos[self.scene.robot.arm_qpos_adr] = q
        mujoco.mj_kinematics(self.model, self.data)

    def _tool_point(self) -> tuple[float, float, float]:
        p = self.data.site_xpos[self.scene.robot.tool_site_id]
        return (float(p[0]), float(p[1]), float(p[2]))

    def _load(self, q: np.ndarray, width: float, X_WO: SE3) -> None:
        """Arm at ``q``, the free fingers at gap ``width`` (the calibrated joint positions of
        every gripper joint), brick at ``X_WO``; kinematics and contacts."""
        m, d, sc = self.model, self.data, self.scene
        d.qpos[sc.robot.arm_qpos_adr] = q
        if width != self._width:  # widths stay the same for most of a plan
            self._width = width
            self._gripper_qpos = sc.robot.qpos_for_width(width)
        d.qpos[self._gripper_qpos_adr] = self._gripper_qpos
        sc.set_brick_pose(d, X_WO)
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)

    def pair_kinds(self, X_WO_start: SE3, X_WO_end: SE3) -> np.ndarray:
        """Per geom pair: 1 robot-world, 2 brick-world, 3 brick-world with a geom the brick
        lies beside at the start or the end (within the clearance plus the tracking tolerance
        of it there: a problem in the transport only, see the module docstring), 4 one it
        rests against there (within the clearance: the floor under it; in the transport
        only), 0 not checked; shape (ngeom, ngeom), symmetric."""
        ng, sc = self.model.ngeom, self.scene
        robot, world = self._robot, self._world
        kinds = np.zeros((ng, ng), dtype=np.int8)
        kinds[np.ix_(robot, world)] = 1
        kinds[np.ix_(world, robot)] = 1
        held = sc.object.geom_ids
        kinds[np.ix_(held, world)] = 2
        kinds[np.ix_(world, held)] = 2
        held_set = set(held.tolist())
        for X_WO in (X_WO_start, X_WO_end):
            self._load(sc.robot.q_home, 0.0, X_WO)
            d, n = self.data, self.data.ncon
            g1, g2 = d.contact.geom1[:n], d.contact.geom2[:n]
            dist = d.contact.dist[:n]
            near = dist < self.config.clearance + self.config.tracking_tolerance
            for a, b, gap in zip(g1[near].tolist(), g2[near].tolist(), dist[near], strict=True):
                if a in held_set or b in held_set:
                    kind = 4 if gap < self.config.clearance else 3  # rests against, beside
                    kinds[a, b] = kinds[b, a] = max(kinds[a, b], kind)
        return kinds

    def clearance(
        self, q: np.ndarray, width: float, X_WO: SE3, pair_kind: np.ndarray, held: bool
    ) -> tuple[float, tuple[str, str, tuple[float, float, float]] | None]:
        """The pre-flight's collision check at one configuration: the smallest robot-world
        (and, if ``held``, brick-world) distance [m], capped at the detection distance, with
        its pair of geom names and point in world [m] (None when nothing is that near).

        Args:
            q: Arm joint positions [rad].
            width: The fingers' gap [m].
            X_WO: The brick's pose in world.
            pair_kind: Which pairs count (:meth:`pair_kinds`).
            held: Whether the brick is held (its pairs count too).
        """
        return self._closest(q, width, X_WO, pair_kind, held)[:2]

    def _closest(
        self,
        q: np.ndarray,
        width: float,
        X_WO: SE3,
        pair_kind: np.ndarray,
        held: bool,
        vertical: bool = False,
    ) -> tuple[float, tuple[str, str, tuple[float, float, float]] | None, float]:
        """Smallest robot-world (and, if ``held``, brick-world) distance, its pair and point,
        and the smallest distance to report (:attr:`PreflightResult.min_clearance`).

        ``vertical``: held in the lift or the place's descent, where the geoms the brick lies
        beside at its start and goal (kind 3 of :meth:`pair_kinds`) are reported but are no
        problem, and those it rests against (kind 4) neither.
        """
        self._load(q, width, X_WO)
        d, sc = self.data, self.scene
        n = d.ncon
        far = self.config.detection_distance
        if n == 0:
            return far, None, far
        contact = d.contact
        g1, g2 = contact.geom1[:n], contact.geom2[:n]
        kinds = pair_kind[g1, g2]
        dist = contact.dist[:n]
        if not held:
            mask = report = kinds == 1
        elif vertical:
            mask, report = (kinds == 1) | (kinds == 2), (kinds >= 1) & (kinds <= 3)
        else:
            mask = report = kinds > 0
        nearest = float(dist[report].min()) if report.any() else far
        if not mask.any():
            return far, None, nearest
        k = int(np.flatnonzero(mask)[np.argmin(dist[mask])])
        a, b = int(g1[k]), int(g2[k])
        if self._world[a]:
            a, b = b, a
        pos = contact.pos[k]
        return (
            float(dist[k]),
            (
                sc.geom_name(a),
                sc.geom_name(b),
                (float(pos[0]), float(pos[1]), float(pos[2])),
            ),
            nearest,
        )


def start_configuration(scene: Scene, q_start: np.ndarray | None) -> np.ndarray:
    """A copy of ``q_start`` [rad], checked to be one finite angle per arm joint, or of the
    robot's home posture when None.

    Raises:
        PlanError: Wrong length or a non-finite value; the message gives the joint count.
    """
    if q_start is None:
        return scene.robot.q_home.copy()
    q = np.array(q_start, dtype=np.float64).reshape(-1)
    n = scene.robot.n_joints
    if q.shape != (n,) or not np.all(np.isfinite(q)):
        raise PlanError(
            f"a start configuration must be {n} finite joint angles [rad] (one per arm joint of "
            f"{scene.robot.name}), got {np.asarray(q_start).tolist()!r}"
        )
    return q


def check_plan_duration(duration: float) -> None:
    """Refuse a plan longer than :data:`MAX_PLAN_DURATION_S` before it is pre-flighted.

    Args:
        duration: The plan's end time [s].

    Raises:
        PlanError: It is longer (or not finite); the message says what makes plans long.
    """
    if not duration <= MAX_PLAN_DURATION_S:
        raise PlanError(
            f"the timed plan lasts {duration:.4g} s; valid: at most {MAX_PLAN_DURATION_S:g} s "
            "of simulated time (what a pre-flight and a run keep in memory grows with it): "
            "raise the speed override (--speed) or the robot's speed_limits and accel_limits"
        )


def collision_model(scene: Scene, detection_distance: float) -> mujoco.MjModel:
    """A copy of the scene's model for kinematic collision queries (see the module docstring):
    robot and brick geoms get ``detection_distance`` as margin, and contact bits such that the
    robot and the brick each touch the world but not each other."""
    model = copy.deepcopy(scene.model)
    for g in range(model.ngeom):
        if not (model.geom_contype[g] or model.geom_conaffinity[g]):
            continue  # visual only
        if scene.is_robot_geom(g):
            bits = (_ROBOT_CONTYPE, _ROBOT_CONAFFINITY)
            model.geom_margin[g] = detection_distance
        elif scene.is_object_geom(g):
            bits = (_BRICK_CONTYPE, _BRICK_CONAFFINITY)
            model.geom_margin[g] = detection_distance
        else:
            bits = (_WORLD_CONTYPE, _WORLD_CONAFFINITY)
        model.geom_contype[g], model.geom_conaffinity[g] = bits
        model.geom_gap[g] = 0.0
    return model
