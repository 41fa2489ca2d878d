"""Differential-IK controllers: one interface, three methods, chosen by name.

Every controller does resolved-rate control: from the trajectory's feed-forward spatial
velocity V_WG_ff and the pose error e (target minus current, world frame) it asks the tool for

    V_cmd = V_WG_ff + K e            (K = diag(k_p I₃, k_R I₃) [1/s])

and returns the joint velocities q̇ [rad/s] that realise it, with a status:

- ``qp``   (default): mink's FrameTask + PostureTask + ConfigurationLimit + VelocityLimit solved
  with daqp (differential IK as a QP with velocity limits, as in Drake's DiffIK). Never exceeds
  the joint speed limits.
  With mink's CollisionAvoidanceLimit between the robot's geoms and the world's
  (:mod:`pickplace.control.collision`); ``qp-no-collision`` is the same without it.
- ``pinv``: q̇ = J⁺ V_cmd with an SVD pseudo-inverse whose singular values below a cutoff are
  treated as zero (the lecture's pseudo-inverse controller). Not clipped: near a singularity it
  asks for huge speeds.
- ``dls``: damped least squares q̇ = Jᵀ(J Jᵀ + λ² I)⁻¹ V_cmd. Not clipped.

The three near a singularity, measured: ``docs/physics-notes.md`` ("mink 1.3 and the
controllers").
"""

from __future__ import annotations

import copy
import dataclasses
import enum
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import ClassVar

import daqp
import mink
import mujoco
import numpy as np
from mink.lie import SE3

from pickplace.control.collision import Clearance, GripperBodies, RobotWorldCollision
from pickplace.control.kinematics import ArmKinematics
from pickplace.errors import ControllerError, UnknownNameError, require_positive
from pickplace.geometry import pose_error_W_floats
from pickplace.world.scene import Scene


class IKStatus(enum.Enum):
    """Outcome of one IK tick."""

    OK = "ok"
    NO_SOLUTION = "no-solution"
    STUCK = "stuck"
    LIMITED = "limited"


IK_STATUSES: tuple[str, ...] = tuple(s.value for s in IKStatus)

# A commanded twist smaller than this is "at rest": no stuck/limited verdict is drawn from it.
_REST_TWIST = 1e-4
_REST_TWIST_SQ = _REST_TWIST**2
# Fraction of the commanded twist below which the tool counts as stuck (Drake's DiffIK: 0.01).
_STUCK_FRACTION = 0.01


@dataclass(frozen=True)
class ResolvedRateGains:
    """Proportional gains of the pose-error correction.

    Attributes:
        position: Gain on the position error [1/s].
        orientation: Gain on the orientation error [1/s].
    """

    position: float = 10.0
    orientation: float = 10.0

    def __post_init__(self) -> None:
        require_positive("position gain", self.position)
        require_positive("orientation gain", self.orientation)


@dataclass(frozen=True, slots=True)
class IKResult:
    """One IK tick. Every array is new per tick (``error``, ``V_cmd`` and ``x_WG`` are disjoint
    views of one new array), so callers may keep them.

    Attributes:
        qdot: Joint velocities [rad/s].
        status: Outcome.
        V_cmd: Commanded tool spatial velocity [v; ω] in world [m/s, rad/s].
        error: Pose error [position; rotation vector] in world [m, rad].
        J_WG: Tool Jacobian (6, n) at the tick's q (n arm joints).
        x_WG: Tool pose at the tick's q (the commanded tool frame) as mink's wxyz_xyz vector
            [qw, qx, qy, qz, x, y, z] ([-], [m]).
    """

    qdot: np.ndarray
    status: IKStatus
    V_cmd: np.ndarray
    error: np.ndarray
    J_WG: np.ndarray
    x_WG: np.ndarray


class DiffIKController(ABC):
    """Base class: resolved-rate command, then a method-specific velocity solve.

    Args:
        scene: The loaded scene (joint limits, speed limits, home posture).
        dt: Control period [s].
        gains: Resolved-rate gains.
        kinematics: Arm kinematics to use; a new one if omitted.
    """

    name: ClassVar[str]

    collision_held: bool = False
    """Whether the last tick's step met a row of the controller's collision limit (to 1e-9
    m): the limit, not the plan, decided how far the robot moved toward the world. Always
    False for a controller without one (``pinv``, ``dls``, ``qp-no-collision``)."""

    def __init__(
        self,
        scene: Scene,
        dt: float,
        gains: ResolvedRateGains | None = None,
        kinematics: ArmKinematics | None = None,
    ) -> None:
        self.dt = require_positive("control period dt", dt)
        self.scene = scene
        self.gains = gains or ResolvedRateGains()
        self.kinematics = kinematics or ArmKinematics(scene)
        self.v_max = scene.robot.v_max.copy()
        self._K = np.repeat([self.gains.position, self.gains.orientation], 3)  # diag of K
        self._k_p = float(self.gains.position)
        self._k_R = float(self.gains.orientation)

    def command(
        self, q: np.ndarray, X_WG_target: SE3 | np.ndarray, V_WG_ff: np.ndarray
    ) -> IKResult:
        """Joint velocities that move the tool toward ``X_WG_target`` at ``V_WG_ff``.

        Args:
            q: Current (commanded) joint positions [rad].
            X_WG_target: Desired tool pose now, as an SE3 or its wxyz_xyz vector.
            V_WG_ff: Desired tool spatial velocity [v; ω] in world [m/s, rad/s].

        Returns:
            The tick's joint velocities, status, commanded twist, pose error, tool Jacobian
            and tool pose at ``q``, all in new arrays.
        """
        # (isinstance against ndarray: SE3 derives from an ABC, whose isinstance is slow.)
        x_target = X_WG_target if isinstance(X_WG_target, np.ndarray) else X_WG_target.wxyz_xyz
        kin = self.kinematics
        kin.update(q)
        x_WG_floats = kin.wxyz_xyz_list()
        J = kin.J_WG()
        # Pose error and commanded twist in plain float math (six-element NumPy operations
        # cost more in call overhead than in arithmetic).
        e = pose_error_W_floats(x_WG_floats, x_target.tolist())
        v_x, v_y, v_z, w_x, w_y, w_z = V_WG_ff.tolist()
        k_p, k_R = self._k_p, self._k_R
        v_x += k_p * e[0]
        v_y += k_p * e[1]
        v_z += k_p * e[2]
        w_x += k_R * e[3]
        w_y += k_R * e[4]
        w_z += k_R * e[5]
        # One new array holds error, V_cmd and x_WG (three disjoint views): one allocation.
        arrays = np.array((*e, v_x, v_y, v_z, w_x, w_y, w_z, *x_WG_floats))
        error, V_cmd, x_WG = arrays[:6], arrays[6:12], arrays[12:]
        qdot, status = self._solve(q, J, V_cmd, x_WG)
        if status is IKStatus.OK:
            V_sq = v_x * v_x + v_y * v_y + v_z * v_z + w_x * w_x + w_y * w_y + w_z * w_z
            if V_sq > _REST_TWIST_SQ:
                achieved = float(V_cmd.dot(J.dot(qdot))) / V_sq
                if achieved < _STUCK_FRACTION:
                    status = IKStatus.STUCK
        return IKResult(qdot=qdot, status=status, V_cmd=V_cmd, error=error, J_WG=J, x_WG=x_WG)

    def follow_joints(self, q: np.ndarray | None, q_dot: np.ndarray | None = None) -> None:
        """Where the joints should be besides the tool: a planned joint path's ``q`` [rad]
        and ``q_dot`` [rad/s] (a C-space motion), or None for the home posture.

        The base controllers have no posture term (their joint motion is the least-norm one
        for the tool's), so this does nothing; the QP steers its null space with it.
        """
        del q, q_dot

    def observe_world(self, mocap_pos: np.ndarray, mocap_quat: np.ndarray) -> None:
        """Take the world's moving bodies' poses (every mocap body: an obstacle a fault moves)
        into the IK's own data, so that the next commands see them.

        Args:
            mocap_pos: The simulation's ``data.mocap_pos`` (nmocap, 3) [m].
            mocap_quat: Its ``data.mocap_quat`` (nmocap, 4), wxyz.
        """
        data = self.kinematics.data
        data.mocap_pos[:] = mocap_pos
        data.mocap_quat[:] = mocap_quat

    def set_gripper_width(self, width: float) -> None:
        """The fingers' gap for the next commands [m]; only a controller that keeps the robot
        clear of the world (``qp`` with its collision limit) uses it.

        Args:
            width: The gap the fingers are at [m].
        """
        return  # pinv and dls see no geometry

    @abstractmethod
    def _solve(
        self, q: np.ndarray, J: np.ndarray, V_cmd: np.ndarray, x_WG: np.ndarray
    ) -> tuple[np.ndarray, IKStatus]:
        """Joint velocities [rad/s] realising ``V_cmd`` and a status.

        Args:
            q: Joint positions [rad], loaded into :attr:`kinematics`.
            J: Tool Jacobian (6, n) at q.
            V_cmd: Commanded tool spatial velocity [v; ω] in world [m/s, rad/s].
            x_WG: Tool pose at q [qw, qx, qy, qz, x, y, z] ([-], [m]).
        """


class PinvController(DiffIKController):
    """q̇ = J⁺ V with an SVD pseudo-inverse.

    Args:
        cutoff: Singular values below this are treated as zero (their directions get no
            motion) [same units as σ: m/rad for translation rows].
    """

    name = "pinv"

    def __init__(self, scene: Scene, dt: float, cutoff: float = 1e-4, **kwargs: object) -> None:
        super().__init__(scene, dt, **kwargs)  # type: ignore[arg-type]
        self.cutoff = require_positive("pinv cutoff", cutoff)

    def _solve(
        self, q: np.ndarray, J: np.ndarray, V_cmd: np.ndarray, x_WG: np.ndarray
    ) -> tuple[np.ndarray, IKStatus]:
        U, s, Vt = np.linalg.svd(J, full_matrices=False)
        cutoff = self.cutoff  # > 0, so σ > cutoff also guards the division
        s_inv = np.array([1.0 / sigma if sigma > cutoff else 0.0 for sigma in s.tolist()])
        s_inv *= V_cmd.dot(U)  # Σ⁺ Uᵀ V
        return s_inv.dot(Vt), IKStatus.OK  # V Σ⁺ Uᵀ V_cmd


class DLSController(DiffIKController):
    """Damped least squares q̇ = Jᵀ(J Jᵀ + λ² I)⁻¹ V.

    Args:
        damping: λ [same units as σ].
    """

    name = "dls"

    def __init__(self, scene: Scene, dt: float, damping: float = 0.05, **kwargs: object) -> None:
        super().__init__(scene, dt, **kwargs)  # type: ignore[arg-type]
        self.damping = require_positive("dls damping", damping)
        self._damping_sq_I = self.damping**2 * np.eye(6)

    def _solve(
        self, q: np.ndarray, J: np.ndarray, V_cmd: np.ndarray, x_WG: np.ndarray
    ) -> tuple[np.ndarray, IKStatus]:
        JJt = J.dot(J.T)
        JJt += self._damping_sq_I
        return np.linalg.solve(JJt, V_cmd).dot(J), IKStatus.OK  # Jᵀ (J Jᵀ + λ² I)⁻¹ V


#: The control period [s] at which :attr:`QPWeights.posture_gain` is the posture task's gain
#: per tick (the loop's default 100 Hz); other periods close the same fraction per second.
POSTURE_GAIN_PERIOD = 0.01


@dataclass(frozen=True)
class QPWeights:
    """Costs of the QP controller's tasks.

    Attributes:
        position_cost: FrameTask position cost [1/m].
        orientation_cost: FrameTask orientation cost [1/rad].
        posture_cost: PostureTask cost toward the home posture [1/rad]; small, so that it
            acts in the frame task's nullspace rather than fighting it.
        posture_gain: Fraction of the posture error the posture task asks to close per tick
            of :data:`POSTURE_GAIN_PERIOD` (the default control period); at another period the
            same fraction per second (:meth:`posture_gain_at`), so that the pre-flight's
            coarser ticks move the null space as the run's ticks do.
        damping: Levenberg-Marquardt damping added to the Hessian diagonal.
        limit_gain: ConfigurationLimit gain (fraction of the distance to a limit per tick).
        limit_margin: Distance kept from the joint limits [rad].
        collision_limit: Keep the robot's geoms clear of the world's with mink's
            CollisionAvoidanceLimit (:mod:`pickplace.control.collision`).
        collision_min_distance: Distance the collision limit keeps between a robot geom and a
            fixed world geom (floor, bins) [m]: 2 mm, below the pre-flight's 5 mm clearance,
            so a plan the pre-flight passed (fingers 8 mm over a bin floor at the pick) is
            never held back by it.
        collision_detection_distance: Fixed-world pairs closer than this get a constraint
            row [m]: 30 mm, more than d_min plus a tick's approach at the fastest robot
            surface of the bundled robots' nominal runs (1.5 m/s, 15 mm a tick at 100 Hz),
            so a pair is seen before it is within d_min.
        moving_min_distance: Distance kept from the world's moving bodies (mocap bodies: an
            obstacle a fault puts in the path during the run) [m]: 20 mm. The plan never came
            near them, so nothing the plan needs is held back, and the physical arm, which
            lags a command stopped within a few ticks by 5–15 mm (docs/physics-notes.md,
            "The collision limit"), stays clear of it.
        moving_detection_distance: Moving-body pairs closer than this get a row [m]: 50 mm,
            d_min plus a tick's approach at 1.5 m/s and as much again.
        collision_gain: Fraction of the distance in excess of d_min that a tick may close
            [-], in (0, 1] (mink's default value, here per tick): the excess shrinks to 15 %
            a tick. 0.5 braked the planner's path sweep (20 mm a tick) on its descent to the
            pick, whose fingers stop about 10 mm above the bin floor, and changed the
            nominal plan's timing; 0.85 leaves every nominal path unbraked.
    """

    position_cost: float = 1.0
    orientation_cost: float = 1.0
    posture_cost: float = 1e-3
    posture_gain: float = 0.1
    damping: float = 1e-12
    limit_gain: float = 0.95
    limit_margin: float = 0.005
    collision_limit: bool = True
    collision_min_distance: float = 0.002
    collision_detection_distance: float = 0.03
    moving_min_distance: float = 0.02
    moving_detection_distance: float = 0.05
    collision_gain: float = 0.85

    def __post_init__(self) -> None:
        """Validate the posture gain and the collision limit's settings."""
        if not 0.0 < self.posture_gain <= 1.0:
            raise ControllerError(f"posture gain {self.posture_gain}; valid: (0, 1]")
        self.fixed_clearance()
        self.moving_clearance()
        if not 0.0 < self.collision_gain <= 1.0:
            raise ControllerError(f"collision limit gain {self.collision_gain}; valid: (0, 1]")

    def posture_gain_at(self, dt: float) -> float:
        """The posture task's gain per tick of period ``dt`` [s]: the fraction of the error
        :attr:`posture_gain` closes per :data:`POSTURE_GAIN_PERIOD`, as a rate, closed over
        ``dt``: ``1 − (1 − posture_gain)^(dt / POSTURE_GAIN_PERIOD)``. A gain per tick alone
        would make the null space converge five times slower per second at the pre-flight's
        20 Hz than in a 100 Hz run: on a 7-joint arm the pre-flight then predicted an elbow
        0.58 rad from the run's, 25 mm from a wall that the run's forearm touched
        (``panda-hand``, ``pick-place-uniform`` seed 98741)."""
        ratio = require_positive("control period dt", dt) / POSTURE_GAIN_PERIOD
        if ratio == 1.0:
            return self.posture_gain
        return 1.0 - (1.0 - self.posture_gain) ** ratio

    def fixed_clearance(self) -> Clearance:
        """The collision limit's distances from the fixed world."""
        return Clearance(self.collision_min_distance, self.collision_detection_distance)

    def moving_clearance(self) -> Clearance:
        """The collision limit's distances from the world's moving bodies."""
        return Clearance(self.moving_min_distance, self.moving_detection_distance)


class QPController(DiffIKController):
    """mink FrameTask + PostureTask + ConfigurationLimit + VelocityLimit, solved with daqp.

    The commanded twist becomes the frame task's target one tick ahead,
    X_WG_target' = (p + v·dt, exp(ω·dt)·R), so with task gain 1 the QP asks for exactly V_cmd.

    Two backends give the same answer (tested to 1e-8):

    - ``"fast"`` (default): the frame task's error and Jacobian come from mink's public
      ``compute_error``/``compute_jacobian`` every tick and are weighted with the task's cost
      and gain; the posture task's are read from the task (on hinge/slide-only models its
      error is simply q − q_target, otherwise mink's ``compute_qp_residual`` gives it); the
      joint-position and joint-speed limits are merged into simple bounds; the QP is
      assembled in preallocated buffers and daqp is called directly. Measured (median µs
      a solve on nominal-run states, one process): this 37; with compute_qp_residual 46;
      with mink's limit rows instead of the merged bounds 88; through qpsolvers instead of
      the direct daqp call 69; mink.solve_ik 159.
    - ``"mink"``: ``mink.solve_ik(..., solver="daqp")`` on the same tasks and limits.

    The frame task's target is an SE3 owned by the controller and rewritten in place every
    tick (see :meth:`set_frame_target`).

    Args:
        weights: Task costs and limit settings.
        backend: ``"fast"`` or ``"mink"``.
    """

    name = "qp"
    BACKENDS: ClassVar[tuple[str, ...]] = ("fast", "mink")

    def __init__(
        self,
        scene: Scene,
        dt: float,
        weights: QPWeights | None = None,
        backend: str = "fast",
        **kwargs: object,
    ) -> None:
        w = weights or QPWeights()
        if w.collision_limit and kwargs.get("kinematics") is None:
            # Its own copy of the arm-only model: the fingers are moved in it to their gap.
            kwargs["kinematics"] = ArmKinematics(scene, model=copy.deepcopy(scene.arm_model))
        super().__init__(scene, dt, **kwargs)  # type: ignore[arg-type]
        if backend not in self.BACKENDS:
            raise UnknownNameError("qp backend", backend, self.BACKENDS)
        self.backend = backend
        self.weights = w
        model = self.kinematics.model
        self.configuration = self.kinematics.configuration
        self.frame_task = mink.FrameTask(
            self.kinematics.tool_site,
            "site",
            position_cost=w.position_cost,
            orientation_cost=w.orientation_cost,
            gain=1.0,
        )
        self.posture_task = mink.PostureTask(model, cost=w.posture_cost, gain=w.posture_gain_at(dt))
        self.posture_task.set_target(scene.robot.q_home)
        self.tasks: list[mink.Task] = [self.frame_task, self.posture_task]
        self.configuration_limit = mink.ConfigurationLimit(
            model, gain=w.limit_gain, min_distance_from_limits=w.limit_margin
        )
        self.velocity_limit = mink.VelocityLimit(
            model, dict(zip(scene.robot.arm_joint_names, self.v_max.tolist(), strict=True))
        )
        self.limits: list[mink.Limit] = [self.configuration_limit, self.velocity_limit]
        self.collision: RobotWorldCollision | None = None
        self._gripper: GripperBodies | None = None
        if w.collision_limit:
            if model is scene.arm_model:
                raise ControllerError(
                    "the qp collision limit moves the fingers in the IK's model: give it "
                    "kinematics on a copy of the scene's arm_model"
                )
            self.collision = RobotWorldCollision(
                scene,
                model,
                dt,
                fixed=w.fixed_clearance(),
                moving=w.moving_clearance(),
                gain=w.collision_gain,
            )
            self._gripper = GripperBodies(scene, model)
            self._gripper.set_width(scene.robot.home_width)
            self.limits += self.collision.limits
        # The collision rows of the last solve (G Δq ≤ h), for the status.
        self._G_collision = np.zeros((0, model.nv))
        self._h_collision = np.zeros(0)
        # The frame task's target: one SE3 whose parameter vector is rewritten every tick.
        self._X_WG_next = SE3(wxyz_xyz=np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
        self._x_WG_next = self._X_WG_next.wxyz_xyz
        self.frame_task.transform_target_to_world = self._X_WG_next
        # With hinge and slide joints only, q ⊖ q_target is q − q_target (nq = nv) and the
        # posture Jacobian is the identity: no per-tick call into mink for the posture task.
        joint_types = np.asarray(model.jnt_type)
        self._posture_is_difference = bool(
            model.nq == model.nv
            and np.all(
                (joint_types == mujoco.mjtJoint.mjJNT_HINGE)
                | (joint_types == mujoco.mjtJoint.mjJNT_SLIDE)
            )
        )
        # Buffers of the fast QP, and the parts of it that only change with the tasks' costs
        # and gains (refreshed by _refresh_task_weights whenever those change).
        nv = model.nv
        self._H = np.zeros((nv, nv))
        self._H_diag = self._H.reshape(-1)[:: nv + 1]  # a view of H's diagonal
        self._c = np.zeros(nv)
        self._A_empty = np.zeros((0, nv))
        self._sense = np.zeros(nv, dtype=np.int32)
        self._task_weights_key: tuple[object, ...] = ()
        self._frame_unit_cost = True
        self._frame_cost_col = np.ones((self.frame_task.k, 1))
        self._frame_gain_cost = np.ones(self.frame_task.k)
        self._frame_unit_gain_cost = True
        self._posture_gain_cost = np.zeros(nv)
        self._posture_gain_cost_sq = np.zeros(nv)
        self._H_diag_const = np.zeros(nv)
        # Simple bounds on Δq (see bounds).
        self._limit_gain = float(w.limit_gain)
        self._q_max = self.configuration_limit.upper.tolist()
        self._q_min = self.configuration_limit.lower.tolist()
        self._dq_max = (self.v_max * self.dt).tolist()
        self._lower = np.empty(nv)
        self._upper = np.empty(nv)
        self._bound_floats: tuple[list[float], list[float]] = ([], [])
        self._bounds_into(scene.robot.q_home)
        self._solve_qp: Callable[[np.ndarray], np.ndarray | None] = (
            self._solve_fast if backend == "fast" else self._solve_mink
        )

    def follow_joints(self, q: np.ndarray | None, q_dot: np.ndarray | None = None) -> None:
        """Aim the posture task at a planned joint path (``q`` [rad], ``q_dot`` [rad/s]), or
        back at the home posture (``q`` None).

        The posture task closes ``posture_gain`` of its error per tick in the frame task's
        null space, so its target leads the path by ``q_dot · dt / posture_gain``: the null
        space then moves at ``q_dot`` and closes the remaining error as before.
        """
        if q is None:
            self.posture_task.set_target(self.scene.robot.q_home)
            return
        target = np.asarray(q, dtype=np.float64)
        if q_dot is not None:
            target = target + np.asarray(q_dot) * (self.dt / self.posture_task.gain)
        self.posture_task.set_target(target)

    def set_frame_target(
        self, x_WG: np.ndarray | Sequence[float], V_cmd: np.ndarray | Sequence[float]
    ) -> None:
        """Aim the frame task one tick ahead of ``x_WG`` (wxyz_xyz) along ``V_cmd``.

        Target: position p + v·dt [m], orientation exp(ω·dt)·R (ω in world [rad/s]). Plain
        float math, written into the controller's target SE3, which the frame task then
        holds (a caller that keeps ``frame_task.transform_target_to_world`` sees it change
        on the next tick).

        Args:
            x_WG: Tool pose [qw, qx, qy, qz, x, y, z] ([-], [m]).
            V_cmd: Commanded tool spatial velocity [v; ω] in world [m/s, rad/s].
        """
        if isinstance(x_WG, np.ndarray):
            x_WG = x_WG.tolist()
        if isinstance(V_cmd, np.ndarray):
            V_cmd = V_cmd.tolist()
        qw, qx, qy, qz, px, py, pz = x_WG
        vx, vy, vz, wx, wy, wz = V_cmd
        dt = self.dt
        speed = math.sqrt(wx * wx + wy * wy + wz * wz)
        if speed > 0.0:
            # exp(ω dt) = (cos(|ω| dt / 2), sin(|ω| dt / 2) ω/|ω|), applied on the left.
            half_angle = 0.5 * dt * speed
            sw = math.cos(half_angle)
            k = math.sin(half_angle) / speed
            sx, sy, sz = k * wx, k * wy, k * wz
            qw, qx, qy, qz = (
                sw * qw - sx * qx - sy * qy - sz * qz,
                sw * qx + sx * qw + sy * qz - sz * qy,
                sw * qy + sy * qw + sz * qx - sx * qz,
                sw * qz + sz * qw + sx * qy - sy * qx,
            )
        self._x_WG_next[:] = (qw, qx, qy, qz, px + vx * dt, py + vy * dt, pz + vz * dt)
        self.frame_task.transform_target_to_world = self._X_WG_next

    def observe_world(self, mocap_pos: np.ndarray, mocap_quat: np.ndarray) -> None:
        """As :meth:`DiffIKController.observe_world`; the collision limit's broad phase then
        recomputes the world geoms' bounds at the next tick."""
        super().observe_world(mocap_pos, mocap_quat)
        if self.collision is not None:
            self.collision.world_moved()

    def set_gripper_width(self, width: float) -> None:
        """The fingers' gap for the next commands [m]: with the collision limit, the IK's
        model places its gripper bodies there (cheap when it has not changed)."""
        if self._gripper is not None:
            self._gripper.set_width(width)

    def _solve_mink(self, q: np.ndarray) -> np.ndarray | None:
        self._bounds_into(q)
        if self.collision is not None:  # the same rows, for the status only
            self._G_collision, self._h_collision = self.collision.rows(self.configuration.data)
        try:
            return mink.solve_ik(
                self.configuration,
                self.tasks,
                self.dt,
                solver="daqp",
                damping=self.weights.damping,
                limits=self.limits,
            )
        except mink.NoSolutionFound:
            return None

    def bounds(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-joint bounds on Δq [rad]: the tighter of speed limit and distance to limit,
        upper = min(v_max dt, g (q_max − q)) and lower = max(−v_max dt, −g (q − q_min)), with
        q_max, q_min the joint limits less the margin and g the limit gain.

        Args:
            q: Joint positions [rad].

        Returns:
            New arrays (lower, upper) [rad].
        """
        lower, upper = self._bounds_floats(q)
        return np.array(lower), np.array(upper)

    def _bounds_floats(self, q: np.ndarray) -> tuple[list[float], list[float]]:
        """:meth:`bounds` as lists of floats (lower, upper) [rad] (plain float math)."""
        g = self._limit_gain
        lower: list[float] = []
        upper: list[float] = []
        for q_j, q_max, q_min, dq_max in zip(
            q.tolist(), self._q_max, self._q_min, self._dq_max, strict=True
        ):
            hi = g * (q_max - q_j)
            upper.append(dq_max if dq_max < hi else hi)  # NaN-propagating min
            lo = g * (q_min - q_j)  # = −g (q − q_min)
            lower.append(-dq_max if lo < -dq_max else lo)  # NaN-propagating max
        return lower, upper

    def _bounds_into(self, q: np.ndarray) -> None:
        """Write :meth:`bounds` at ``q`` into the QP's bound vectors (and keep the floats)."""
        self._bound_floats = lower, upper = self._bounds_floats(q)
        self._lower[:] = lower
        self._upper[:] = upper

    def _refresh_task_weights(self) -> None:
        """Recompute the QP parts that depend only on the tasks' costs and gains, if those
        changed since the last tick (a cheap check: two byte strings and four floats)."""
        frame, posture = self.frame_task, self.posture_task
        key = (
            frame.cost.tobytes(),
            frame.gain,
            frame.lm_damping,
            posture.cost.tobytes(),
            posture.gain,
            posture.lm_damping,
        )
        if key == self._task_weights_key:
            return
        self._task_weights_key = key
        self._frame_unit_cost = bool(np.all(frame.cost == 1.0))
        self._frame_cost_col = frame.cost[:, None].copy()
        self._frame_gain_cost = frame.gain * frame.cost
        self._frame_unit_gain_cost = bool(np.all(self._frame_gain_cost == 1.0))
        self._posture_gain_cost = posture.gain * posture.cost
        self._posture_gain_cost_sq = self._posture_gain_cost * posture.cost
        # H's constant diagonal: the damping, plus the posture task's WᵀW = diag(cost²) when
        # its Jacobian is the identity.
        self._H_diag_const = np.full(len(posture.cost), self.weights.damping)
        if self._posture_is_difference:
            self._H_diag_const += posture.cost**2

    def _solve_fast(self, q: np.ndarray) -> np.ndarray | None:
        """The QP of :func:`mink.solve_ik` assembled and solved directly.

        Minimise ½ Δqᵀ H Δq + cᵀ Δq subject to the bounds on Δq, where, as mink builds them
        from each task's cost-weighted Jacobian W, error e, gain α and Levenberg-Marquardt
        term μ: H = Σ WᵀW + (damping + Σ μ) I and c = Σ Wᵀ(α cost ⊙ e). The frame task's e
        and Jacobian come from mink's public ``compute_error`` and ``compute_jacobian`` every
        tick; the posture task's target is read from the task every tick and, on
        hinge/slide-only models, its e is q − q_target and its Jacobian the identity.

        Args:
            q: Joint positions [rad]; forward kinematics must already be loaded at q.

        Returns:
            Joint velocities [rad/s] (a new array), or None if daqp found no solution.
        """
        self._refresh_task_weights()
        frame, posture = self.frame_task, self.posture_task
        # Two public calls (each looks the frame pose up again): measured about 2 µs a solve
        # dearer than mink's private joint call and 9 µs cheaper than compute_qp_residual, which
        # weights every tick even at unit cost.
        e = frame.compute_error(self.configuration)  # a new array
        W = frame.compute_jacobian(self.configuration)  # a new array
        if not self._frame_unit_cost:
            W *= self._frame_cost_col
        if not self._frame_unit_gain_cost:
            e *= self._frame_gain_cost  # −(weighted error), in the units of W's rows
        H, c = self._H, self._c
        np.dot(W.T, W, out=H)
        np.dot(e, W, out=c)
        mu = frame.lm_damping * float(e.dot(e)) if frame.lm_damping else 0.0
        if self._posture_is_difference:
            target = posture.target_q
            if target is None:
                raise mink.TargetNotSet(type(posture).__name__)
            r = q - target  # the posture error q ⊖ q_target
            if posture.lm_damping:
                r_weighted = r * self._posture_gain_cost  # −(weighted error)
                mu += posture.lm_damping * float(r_weighted.dot(r_weighted))
            r *= self._posture_gain_cost_sq  # Wᵀ(−weighted error), W = diag(cost)
            c += r
        else:
            W_posture, e_posture, mu_posture = posture.compute_qp_residual(self.configuration)
            H += W_posture.T @ W_posture
            c -= e_posture @ W_posture
            mu += mu_posture
        self._H_diag += self._H_diag_const
        if mu:
            self._H_diag += mu
        self._bounds_into(q)
        if self.collision is None:
            x, _, exitflag, _ = daqp.solve(
                H, c, self._A_empty, self._upper, self._lower, self._sense
            )
        else:
            # The collision limit's rows as general inequalities G Δq ≤ h (daqp's A, with
            # bounds after the nv simple ones: upper h, lower −∞).
            G, h = self._G_collision, self._h_collision = self.collision.rows(
                self.configuration.data
            )
            k = len(h)
            if k == 0:
                x, _, exitflag, _ = daqp.solve(
                    H, c, self._A_empty, self._upper, self._lower, self._sense
                )
            else:
                upper = np.concatenate((self._upper, h))
                lower = np.concatenate((self._lower, np.full(k, -np.inf)))
                sense = np.zeros(len(upper), dtype=np.int32)
                x, _, exitflag, _ = daqp.solve(H, c, G, upper, lower, sense)
        if exitflag < 1:
            return None
        qdot: np.ndarray = x
        qdot /= self.dt  # x is a new array
        return qdot

    def _solve(
        self, q: np.ndarray, J: np.ndarray, V_cmd: np.ndarray, x_WG: np.ndarray
    ) -> tuple[np.ndarray, IKStatus]:
        self.set_frame_target(x_WG, V_cmd)
        qdot = self._solve_qp(q)
        if qdot is None:
            return np.zeros_like(q), IKStatus.NO_SOLUTION
        dt, inv_dt = self.dt, 1.0 / self.dt
        lower, upper = self._bound_floats
        # daqp meets the bounds to its primal tolerance (1e-6 rad a step, 7e-5 of a speed
        # limit at 100 Hz): clip to them, so a bound is never exceeded. A joint whose step
        # sits on its bound (within 1e-9 rad) was limited.
        status = IKStatus.OK
        values = qdot.tolist()
        for j, (v, lo, hi) in enumerate(zip(values, lower, upper, strict=True)):
            dq = v * dt
            if dq > hi:
                qdot[j] = hi * inv_dt
                dq = hi
            elif dq < lo:
                qdot[j] = lo * inv_dt
                dq = lo
            if hi - dq <= 1e-9 or dq - lo <= 1e-9:
                status = IKStatus.LIMITED
        h = self._h_collision
        # A collision row met (to 1e-9 m) also limited the step.
        met = bool(len(h)) and bool(np.any(self._G_collision.dot(qdot) * dt >= h - 1e-9))
        self.collision_held = met
        if met and status is IKStatus.OK:
            status = IKStatus.LIMITED
        return qdot, status


class QPNoCollisionController(QPController):
    """The ``qp`` controller with its collision limit off (:attr:`QPWeights.collision_limit`
    False): the same tasks, joint limits and speed limits, nothing kept from the world. A name
    of its own, so that the planner's pre-flight runs it too and a sweep can compare it
    (``--compare controller=qp,qp-no-collision``).

    Args:
        weights: As :class:`QPController`'s; their ``collision_limit`` is set False.
    """

    name = "qp-no-collision"

    def __init__(
        self, scene: Scene, dt: float, weights: QPWeights | None = None, **kwargs: object
    ) -> None:
        off = dataclasses.replace(weights or QPWeights(), collision_limit=False)
        super().__init__(scene, dt, weights=off, **kwargs)  # type: ignore[arg-type]


CONTROLLERS: dict[str, type[DiffIKController]] = {
    c.name: c for c in (QPController, QPNoCollisionController, PinvController, DLSController)
}


def without_collision_limit(name: str) -> str:
    """The name of controller ``name`` without a collision limit: ``qp`` → ``qp-no-collision``;
    any other name is returned as it is (unknown names are left to :func:`make_controller`)."""
    return QPNoCollisionController.name if name == QPController.name else name


def make_controller(name: str, scene: Scene, dt: float, **kwargs: object) -> DiffIKController:
    """Build the controller called ``name`` (one of :data:`CONTROLLERS`).

    Raises:
        UnknownNameError: ``name`` is not a controller; the message lists the valid ones.
    """
    try:
        cls = CONTROLLERS[name]
    except KeyError:
        raise UnknownNameError("controller", name, CONTROLLERS) from None
    try:
        return cls(scene, dt, **kwargs)  # type: ignore[arg-type]
    except TypeError as exc:
        raise ControllerError(f"controller '{name}': {exc}") from exc
