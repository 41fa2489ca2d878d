"""The kinematic pre-flight: a plan executed by the run's own controller, before any physics.

The IK never reads the simulated state: it integrates its commanded joint positions open loop
(:mod:`pickplace.sim`). Running the same controller over the whole plan kinematically therefore
predicts the commanded joint path, up to the coarser rate the pre-flight runs at
(:attr:`PreflightConfig.rate_hz`). At every pre-flight tick it checks, in this order:

1. the IK: a solution exists, and the commanded tool stays within
   :attr:`PreflightConfig.tracking_tolerance` of the plan;
2. the joints: each one at least :attr:`PreflightConfig.joint_margin` inside its range, and no
   commanded speed above its limit;
3. the Jacobian: σmin at least :attr:`PreflightConfig.min_singular_value`;
4. collisions: every robot geom (arm links, palm, fingers at their commanded width, or at the
   grasped brick's width while holding it) and the brick while it is held, against every world
   geom (bins, floor, obstacles), at least :attr:`PreflightConfig.clearance` apart. MuJoCo's own
   collision detection (``mj_collision`` with geom margins) runs on a kinematic copy of the
   scene's model; the robot never collides with the brick there (the grasp is the physics'
   job), and the held brick ignores the geoms it rests on at its start and goal poses.

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

from pickplace.checks import grasp_width
from pickplace.controllers import IKResult, IKStatus, make_controller
from pickplace.errors import require_positive
from pickplace.plan import Plan
from pickplace.scene import Scene

# Contact bits of the kinematic copy: the robot touches the world, the brick touches the
# world, and neither touches the other (nor the robot itself).
_WORLD_CONTYPE, _WORLD_CONAFFINITY = 1, 1 | 2
_ROBOT_CONTYPE, _ROBOT_CONAFFINITY = 2, 0
_BRICK_CONTYPE, _BRICK_CONAFFINITY = 4, 1
# A brick geom within this distance of a world geom rests on it [m].
_SUPPORT_DISTANCE = 1e-3


@dataclass(frozen=True)
class PreflightConfig:
    """Rate and thresholds of the pre-flight.

    Attributes:
        rate_hz: Rate at which the controller is run and every check made [Hz]. 20 Hz predicts
            the same problems as the 100 Hz control rate on the measured plans at a fifth of
            the cost (see ``../shared/notes/planning-failures.md``).
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
        """Validate every field (all must be finite numbers > 0)."""
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


@dataclass(frozen=True)
class Problem:
    """The first thing that makes a plan infeasible.

    Attributes:
        t: Plan time [s].
        kind: ``"ik"``, ``"joint-limit"``, ``"speed-limit"``, ``"singularity"`` or
            ``"collision"``; the planner adds ``"grip"`` (the brick cannot be carried, see
            :data:`pickplace.planner.GRIP_PROBLEM`).
        text: One line for a person: what, where, how much.
        point_W: Where it happened in world [m]: the contact point, or the limited joint's
            anchor, or the tool.
    """

    t: float
    kind: str
    text: str
    point_W: tuple[float, float, float]

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


class Preflight:
    """Runs plans through a controller and the scene's geometry without physics.

    Args:
        scene: The scene (its model is copied, never changed).
        controller: Name of the run's controller (``qp``, ``pinv`` or ``dls``).
        config: Rate and thresholds.
    """

    def __init__(
        self, scene: Scene, controller: str, config: PreflightConfig | None = None
    ) -> None:
        self.scene = scene
        self.config = config or PreflightConfig()
        self.dt = 1.0 / self.config.rate_hz
        self.controller = make_controller(controller, scene, self.dt)
        self.model = collision_model(scene, self.config.detection_distance)
        self.data = mujoco.MjData(self.model)
        self._names = scene.arm_joint_names
        lo, hi = scene.model.jnt_range[scene.finger_joint_ids].T
        self._fingers = list(
            zip(scene.finger_qpos_adr.tolist(), lo.tolist(), hi.tolist(), strict=True)
        )

    def run(
        self, plan: Plan, X_WO_start: SE3, X_WO_goal: SE3 | None, stop_at_problem: bool = True
    ) -> PreflightResult:
        """Pre-flight ``plan`` from the home posture.

        Args:
            plan: The plan (its phases say when the brick is held).
            X_WO_start: Brick pose before it is grasped.
            X_WO_goal: Brick pose after it is released (None: it stays at the start).
            stop_at_problem: Stop at the first problem (else check the whole plan).
        """
        cfg, sc, dt = self.config, self.scene, self.dt
        traj, phases = plan.trajectory, plan.phases
        X_GO = plan.X_OG.inverse() if plan.X_OG is not None else None
        width_held = grasp_width(plan, sc)
        held = (phases.grip_closed, phases.release) if phases and X_GO is not None else None
        X_WO_end = X_WO_goal if X_WO_goal is not None else X_WO_start
        pair_kind = self._pair_kinds(X_WO_start, X_WO_end)
        command, sample = self.controller.command, traj.sample
        n = math.floor(traj.end_time / dt + 1e-9) + 1
        times = np.arange(n) * dt
        q_path = np.zeros((n, len(sc.q_home)))
        qdot_path = np.zeros((n, len(sc.q_home)))
        J_path = np.zeros((n, 6, len(sc.q_home)))
        clear_path = np.full(n, cfg.detection_distance)
        limits = _Limits(
            q_lo=sc.q_min + cfg.joint_margin,
            q_hi=sc.q_max - cfg.joint_margin,
            v_lim=sc.v_max * (1.0 + cfg.speed_ratio_tolerance),
            tracking_sq=cfg.tracking_tolerance**2,
        )
        midpoint, half_dt = cfg.midpoint_feedforward, 0.5 * dt
        q = sc.q_home.copy()
        found: Problem | None = None  # the first IK, joint, speed or collision problem
        end = n
        for i in range(n):
            t = float(times[i])
            x, V, width = sample(t)
            if midpoint:
                V = sample(t + half_dt)[1]
            res = command(q, x, V)
            q_path[i], qdot_path[i], J_path[i] = q, res.qdot, res.J_WG
            is_held = held is not None and held[0] <= t < held[1]
            X_WO = X_WO_start if held is None or t < held[0] else X_WO_end
            if is_held and X_GO is not None:
                X_WO = SE3(res.x_WG) @ X_GO
                width = max(width, width_held)
            clearance, contact = self._closest(q, width, X_WO, pair_kind, is_held)
            clear_path[i] = clearance
            if found is None:
                found = self._problem(t, q, x, res, clearance, contact, limits)
                if found is not None and stop_at_problem:
                    end = i + 1
                    break
            q = q + res.qdot * dt
        # σmin of every tick in one batched SVD; a singularity before the first other problem
        # is the plan's first problem.
        sigma = np.linalg.svd(J_path[:end], compute_uv=False)[:, -1]
        low = np.flatnonzero(sigma < cfg.min_singular_value)
        problem = found
        if low.size and (found is None or times[low[0]] < found.t):
            k = int(low[0])
            text = (
                f"the tool Jacobian's smallest singular value is {sigma[k]:.4f} (below "
                f"{cfg.min_singular_value}): near a singularity"
            )
            self._load_arm(q_path[k])
            problem = Problem(float(times[k]), "singularity", text, self._tool_point())
            end = k + 1 if stop_at_problem else end
        q_all = q_path[:end]
        margin = np.minimum(q_all - sc.q_min, sc.q_max - q_all)
        ratio = np.abs(qdot_path[:end]) / sc.v_max
        return PreflightResult(
            problem=problem,
            t_checked=float(times[end - 1]),
            min_clearance=float(clear_path[:end].min()),
            min_joint_margin=float(margin.min()),
            peak_speed_ratio=float(ratio.max()),
            min_singular_value=float(sigma[:end].min()),
            times=times[:end],
            q=q_all,
        )

    def _problem(
        self,
        t: float,
        q: np.ndarray,
        x_plan: np.ndarray,
        res: IKResult,
        clearance: float,
        contact: tuple[str, str, tuple[float, float, float]] | None,
        limits: _Limits,
    ) -> Problem | None:
        """The first of the IK, joint, speed and collision problems at one tick, if any."""
        cfg, sc = self.config, self.scene
        p_cmd = res.x_WG[4:]
        tool = (float(p_cmd[0]), float(p_cmd[1]), float(p_cmd[2]))
        if res.status is IKStatus.NO_SOLUTION:
            return Problem(t, "ik", "the IK finds no solution", tool)
        e = x_plan[4:] - p_cmd
        if float(e @ e) > limits.tracking_sq:
            text = (
                f"the commanded tool falls {math.sqrt(float(e @ e)) * 1000:.0f} mm behind the "
                f"plan (limit {cfg.tracking_tolerance * 1000:.0f} mm; status "
                f"{res.status.value}): unreachable or too fast"
            )
            return Problem(t, "ik", text, tool)
        if (q < limits.q_lo).any() or (q > limits.q_hi).any():
            below, above = q - sc.q_min, sc.q_max - q
            j = int(np.argmin(np.minimum(below, above)))
            side, limit = ("lower", sc.q_min[j]) if below[j] < above[j] else ("upper", sc.q_max[j])
            text = (
                f"{self._names[j]} at {q[j]:.3f} rad is {min(below[j], above[j]):.3f} rad from "
                f"its {side} limit {limit:.3f} rad (margin {cfg.joint_margin} rad)"
            )
            return Problem(t, "joint-limit", text, self._anchor(j))
        speed = np.abs(res.qdot)
        if (speed > limits.v_lim).any():
            j = int(np.argmax(speed / sc.v_max))
            text = (
                f"{self._names[j]} commanded at {speed[j]:.2f} rad/s, "
                f"{speed[j] / sc.v_max[j]:.2f}x its limit {sc.v_max[j]:.2f} rad/s"
            )
            return Problem(t, "speed-limit", text, self._anchor(j))
        if contact is not None and clearance < cfg.clearance:
            a, b, pos = contact
            text = (
                f"{a} comes within {clearance * 1000:.1f} mm of {b} (clearance "
                f"{cfg.clearance * 1000:.0f} mm)"
            )
            return Problem(t, "collision", text, pos)
        return None

    # ------------------------------------------------------------------ geometry

    def _load_arm(self, q: np.ndarray) -> None:
        """Arm at ``q``: kinematics only."""
        self.data.qpos[self.scene.arm_qpos_adr] = q
        mujoco.mj_kinematics(self.model, self.data)

    def _tool_point(self) -> tuple[float, float, float]:
        p = self.data.site_xpos[self.scene.tool_site_id]
        return (float(p[0]), float(p[1]), float(p[2]))

    def _load(self, q: np.ndarray, width: float, X_WO: SE3) -> None:
        """Arm at ``q``, fingers at ``width``, brick at ``X_WO``; kinematics and contacts."""
        m, d, sc = self.model, self.data, self.scene
        d.qpos[sc.arm_qpos_adr] = q
        half = 0.5 * width
        for adr, lo, hi in self._fingers:
            d.qpos[adr] = lo if half < lo else hi if half > hi else half
        sc.set_brick_pose(d, X_WO)
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)

    def _anchor(self, j: int) -> tuple[float, float, float]:
        """World position of arm joint ``j``'s anchor (kinematics loaded by :meth:`_closest`)."""
        p = self.data.xanchor[self.scene.arm_joint_ids[j]]
        return (float(p[0]), float(p[1]), float(p[2]))

    def _pair_kinds(self, X_WO_start: SE3, X_WO_end: SE3) -> np.ndarray:
        """Per geom pair: 1 robot-world, 2 brick-world (not a geom it rests on at the start or
        the end), 0 not checked; shape (ngeom, ngeom), symmetric."""
        ng, sc = self.model.ngeom, self.scene
        robot = np.array([sc.is_robot_geom(g) for g in range(ng)])
        world = np.array([sc.is_world_geom(g) for g in range(ng)])
        kinds = np.zeros((ng, ng), dtype=np.int8)
        kinds[np.ix_(robot, world)] = 1
        kinds[np.ix_(world, robot)] = 1
        brick = sc.brick_geom_id
        kinds[brick, world] = 2
        kinds[world, brick] = 2
        for X_WO in (X_WO_start, X_WO_end):
            self._load(sc.q_home, 0.0, X_WO)
            d, n = self.data, self.data.ncon
            g1, g2 = d.contact.geom1[:n], d.contact.geom2[:n]
            near = d.contact.dist[:n] <= _SUPPORT_DISTANCE
            for a, b in zip(g1[near].tolist(), g2[near].tolist(), strict=True):
                if brick in (a, b):
                    kinds[a, b] = kinds[b, a] = 0  # the brick rests on it
        return kinds

    def _closest(
        self, q: np.ndarray, width: float, X_WO: SE3, pair_kind: np.ndarray, held: bool
    ) -> tuple[float, tuple[str, str, tuple[float, float, float]] | None]:
        """Smallest robot-world (and, if ``held``, brick-world) distance, its pair and point."""
        self._load(q, width, X_WO)
        d, sc = self.data, self.scene
        n = d.ncon
        if n == 0:
            return self.config.detection_distance, None
        contact = d.contact
        g1, g2 = contact.geom1[:n], contact.geom2[:n]
        kinds = pair_kind[g1, g2]
        mask = kinds > 0 if held else kinds == 1
        if not mask.any():
            return self.config.detection_distance, None
        dist = contact.dist[:n]
        k = int(np.flatnonzero(mask)[np.argmin(dist[mask])])
        a, b = int(g1[k]), int(g2[k])
        if sc.is_world_geom(a):
            a, b = b, a
        pos = contact.pos[k]
        return float(dist[k]), (
            sc.geom_name(a),
            sc.geom_name(b),
            (float(pos[0]), float(pos[1]), float(pos[2])),
        )


@dataclass(frozen=True)
class _Limits:
    """Per-tick thresholds of :meth:`Preflight._problem`, precomputed per run."""

    q_lo: np.ndarray
    q_hi: np.ndarray
    v_lim: np.ndarray
    tracking_sq: float


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
        elif g == scene.brick_geom_id:
            bits = (_BRICK_CONTYPE, _BRICK_CONAFFINITY)
            model.geom_margin[g] = detection_distance
        else:
            bits = (_WORLD_CONTYPE, _WORLD_CONAFFINITY)
        model.geom_contype[g], model.geom_conaffinity[g] = bits
        model.geom_gap[g] = 0.0
    return model
