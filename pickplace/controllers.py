"""Differential-IK controllers: one interface, three methods, chosen by name.

Every controller does resolved-rate control: from the trajectory's feed-forward spatial
velocity V_WG_ff and the pose error e (target minus current, world frame) it asks the tool for

    V_cmd = V_WG_ff + K e            (K = diag(k_p I₃, k_R I₃) [1/s])

and returns the joint velocities q̇ [rad/s] that realise it, with a status:

- ``qp``   (default): mink's FrameTask + PostureTask + ConfigurationLimit + VelocityLimit solved
  with daqp (seed lecture 000: differential IK as a QP with velocity limits). Never exceeds
  the joint speed limits.
- ``pinv``: q̇ = J⁺ V_cmd with an SVD pseudo-inverse whose singular values below a cutoff are
  treated as zero (seed 002). Not clipped: near a singularity it asks for huge speeds.
- ``dls``: damped least squares q̇ = Jᵀ(J Jᵀ + λ² I)⁻¹ V_cmd (seed 003). Not clipped.
"""

from __future__ import annotations

import enum
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import daqp
import mink
import mujoco
import numpy as np
from mink.lie import SE3

from pickplace.errors import ControllerError, UnknownNameError, require_positive
from pickplace.kinematics import ArmKinematics, pose_error_W
from pickplace.scene import Scene


class IKStatus(enum.Enum):
    """Outcome of one IK tick."""

    OK = "ok"
    NO_SOLUTION = "no-solution"
    STUCK = "stuck"
    LIMITED = "limited"


IK_STATUSES: tuple[str, ...] = tuple(s.value for s in IKStatus)

# A commanded twist smaller than this is "at rest": no stuck/limited verdict is drawn from it.
_REST_TWIST = 1e-4
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


@dataclass(frozen=True)
class IKResult:
    """One IK tick.

    Attributes:
        qdot: Joint velocities [rad/s].
        status: Outcome.
        V_cmd: Commanded tool spatial velocity [v; ω] in world [m/s, rad/s].
        error: Pose error [position; rotation vector] in world [m, rad].
        J_WG: Tool Jacobian (6, 7) at the tick's q.
    """

    qdot: np.ndarray
    status: IKStatus
    V_cmd: np.ndarray
    error: np.ndarray
    J_WG: np.ndarray


class DiffIKController(ABC):
    """Base class: resolved-rate command, then a method-specific velocity solve.

    Args:
        scene: The loaded scene (joint limits, speed limits, home posture).
        dt: Control period [s].
        gains: Resolved-rate gains.
        kinematics: Arm kinematics to use; a new one if omitted.
    """

    name: ClassVar[str]

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
        self.v_max = scene.v_max.copy()
        self._K = np.repeat([self.gains.position, self.gains.orientation], 3)

    def command(
        self, q: np.ndarray, X_WG_target: SE3 | np.ndarray, V_WG_ff: np.ndarray
    ) -> IKResult:
        """Joint velocities that move the tool toward ``X_WG_target`` at ``V_WG_ff``.

        Args:
            q: Current (commanded) joint positions [rad].
            X_WG_target: Desired tool pose now, as an SE3 or its wxyz_xyz vector.
            V_WG_ff: Desired tool spatial velocity [v; ω] in world [m/s, rad/s].
        """
        x_target = X_WG_target.wxyz_xyz if isinstance(X_WG_target, SE3) else X_WG_target
        kin = self.kinematics
        kin.update(q)
        x_WG = kin.wxyz_xyz()
        J = kin.J_WG()
        error = pose_error_W(x_WG, x_target)
        V_cmd = V_WG_ff + self._K * error
        qdot, status = self._solve(q, x_WG, J, V_cmd)
        if status is IKStatus.OK and float(V_cmd @ V_cmd) > _REST_TWIST**2:
            achieved = float(V_cmd @ (J @ qdot)) / float(V_cmd @ V_cmd)
            if achieved < _STUCK_FRACTION:
                status = IKStatus.STUCK
        return IKResult(qdot=qdot, status=status, V_cmd=V_cmd, error=error, J_WG=J)

    @abstractmethod
    def _solve(
        self, q: np.ndarray, x_WG: np.ndarray, J: np.ndarray, V_cmd: np.ndarray
    ) -> tuple[np.ndarray, IKStatus]:
        """Return joint velocities [rad/s] realising ``V_cmd`` and a status."""


class PinvController(DiffIKController):
    """q̇ = J⁺ V with an SVD pseudo-inverse (seed 002).

    Args:
        cutoff: Singular values below this are treated as zero (their directions get no
            motion) [same units as σ: m/rad for translation rows].
    """

    name = "pinv"

    def __init__(self, scene: Scene, dt: float, cutoff: float = 1e-4, **kwargs: object) -> None:
        super().__init__(scene, dt, **kwargs)  # type: ignore[arg-type]
        self.cutoff = require_positive("pinv cutoff", cutoff)

    def _solve(
        self, q: np.ndarray, x_WG: np.ndarray, J: np.ndarray, V_cmd: np.ndarray
    ) -> tuple[np.ndarray, IKStatus]:
        U, s, Vt = np.linalg.svd(J, full_matrices=False)
        s_inv = np.where(s > self.cutoff, 1.0 / np.where(s > 0.0, s, 1.0), 0.0)
        return Vt.T @ (s_inv * (U.T @ V_cmd)), IKStatus.OK


class DLSController(DiffIKController):
    """Damped least squares q̇ = Jᵀ(J Jᵀ + λ² I)⁻¹ V (seed 003).

    Args:
        damping: λ [same units as σ].
    """

    name = "dls"

    def __init__(self, scene: Scene, dt: float, damping: float = 0.05, **kwargs: object) -> None:
        super().__init__(scene, dt, **kwargs)  # type: ignore[arg-type]
        self.damping = require_positive("dls damping", damping)

    def _solve(
        self, q: np.ndarray, x_WG: np.ndarray, J: np.ndarray, V_cmd: np.ndarray
    ) -> tuple[np.ndarray, IKStatus]:
        JJt = J @ J.T
        JJt.flat[:: JJt.shape[0] + 1] += self.damping**2
        return J.T @ np.linalg.solve(JJt, V_cmd), IKStatus.OK


@dataclass(frozen=True)
class QPWeights:
    """Costs of the QP controller's tasks.

    Attributes:
        position_cost: FrameTask position cost [1/m].
        orientation_cost: FrameTask orientation cost [1/rad].
        posture_cost: PostureTask cost toward the home posture [1/rad]; small, so that it
            acts in the frame task's nullspace rather than fighting it.
        posture_gain: Fraction of the posture error the posture task asks to close per tick.
        damping: Levenberg-Marquardt damping added to the Hessian diagonal.
        limit_gain: ConfigurationLimit gain (fraction of the distance to a limit per tick).
        limit_margin: Distance kept from the joint limits [rad].
    """

    position_cost: float = 1.0
    orientation_cost: float = 1.0
    posture_cost: float = 1e-3
    posture_gain: float = 0.1
    damping: float = 1e-12
    limit_gain: float = 0.95
    limit_margin: float = 0.005


class QPController(DiffIKController):
    """mink FrameTask + PostureTask + ConfigurationLimit + VelocityLimit, solved with daqp.

    The commanded twist becomes the frame task's target one tick ahead,
    X_WG_target' = (p + v·dt, exp(ω·dt)·R), so with task gain 1 the QP asks for exactly V_cmd.

    Two backends give the same answer (tested to 1e-8):

    - ``"fast"`` (default): the tasks' residuals come from mink every tick, but the constant
      parts (posture weight, limit structure) are built once, the joint-position and
      joint-speed limits are merged into simple bounds, and daqp is called directly.
    - ``"mink"``: ``mink.solve_ik(..., solver="daqp")`` on the same tasks and limits.

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
        super().__init__(scene, dt, **kwargs)  # type: ignore[arg-type]
        if backend not in self.BACKENDS:
            raise UnknownNameError("qp backend", backend, self.BACKENDS)
        self.backend = backend
        self.weights = w = weights or QPWeights()
        model = self.kinematics.model
        self.configuration = self.kinematics.configuration
        self.frame_task = mink.FrameTask(
            self.kinematics.tool_site,
            "site",
            position_cost=w.position_cost,
            orientation_cost=w.orientation_cost,
            gain=1.0,
        )
        self.posture_task = mink.PostureTask(model, cost=w.posture_cost, gain=w.posture_gain)
        self.posture_task.set_target(scene.q_home)
        self.tasks: list[mink.Task] = [self.frame_task, self.posture_task]
        self.configuration_limit = mink.ConfigurationLimit(
            model, gain=w.limit_gain, min_distance_from_limits=w.limit_margin
        )
        self.velocity_limit = mink.VelocityLimit(
            model, dict(zip(scene.names.arm_joints, self.v_max.tolist(), strict=True))
        )
        self.limits: list[mink.Limit] = [self.configuration_limit, self.velocity_limit]
        # Constant parts of the fast QP.
        nv = model.nv
        self._A_empty = np.zeros((0, nv))
        self._dq_max = self.v_max * self.dt
        self._q_lo = self.configuration_limit.lower.copy()
        self._q_hi = self.configuration_limit.upper.copy()
        self._H_const = np.eye(nv) * (w.posture_cost**2 + w.damping)
        self._unit_quat = np.array([1.0, 0.0, 0.0, 0.0])
        self._last_bounds = self.bounds(scene.q_home)
        self._solve_qp: Callable[[np.ndarray], np.ndarray | None] = (
            self._solve_fast if backend == "fast" else self._solve_mink
        )

    def set_frame_target(self, x_WG: np.ndarray, V_cmd: np.ndarray) -> None:
        """Aim the frame task one tick ahead of ``x_WG`` (wxyz_xyz) along ``V_cmd``.

        Target: position p + v·dt, orientation exp(ω·dt)·R (ω in world).
        """
        step = self._unit_quat.copy()
        mujoco.mju_quatIntegrate(step, V_cmd[3:], self.dt)  # exp(ω dt)
        target = np.empty(7)
        mujoco.mju_mulQuat(target[:4], step, x_WG[:4])
        target[4:] = x_WG[4:] + V_cmd[:3] * self.dt
        self.frame_task.set_target(SE3(wxyz_xyz=target))

    def _solve_mink(self, q: np.ndarray) -> np.ndarray | None:
        self._last_bounds = self.bounds(q)
        try:
            return mink.solve_ik(
                self.configuration, self.tasks, self.dt, solver="daqp", limits=self.limits
            )
        except mink.NoSolutionFound:
            return None

    def bounds(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-joint bounds on Δq [rad]: the tighter of speed limit and distance to limit."""
        g = self.weights.limit_gain
        upper = np.minimum(self._dq_max, g * (self._q_hi - q))
        lower = np.maximum(-self._dq_max, -g * (q - self._q_lo))
        return lower, upper

    def _solve_fast(self, q: np.ndarray) -> np.ndarray | None:
        W, e, mu = self.frame_task.compute_qp_residual(self.configuration)
        e_posture = -self.weights.posture_gain * self.posture_task.compute_error(self.configuration)
        H = W.T @ W + self._H_const
        H.flat[:: H.shape[0] + 1] += mu
        c = -(e @ W) - self.weights.posture_cost**2 * e_posture
        lower, upper = self._last_bounds = self.bounds(q)
        x, _, exitflag, _ = daqp.solve(H, c, self._A_empty, upper, lower)
        if exitflag < 1:
            return None
        return np.asarray(x) / self.dt

    def _solve(
        self, q: np.ndarray, x_WG: np.ndarray, J: np.ndarray, V_cmd: np.ndarray
    ) -> tuple[np.ndarray, IKStatus]:
        self.set_frame_target(x_WG, V_cmd)
        qdot = self._solve_qp(q)
        if qdot is None:
            return np.zeros_like(q), IKStatus.NO_SOLUTION
        lower, upper = self._last_bounds
        dq = qdot * self.dt
        # A joint whose step sits on its bound (within 1e-9 rad) was limited.
        slack = min(float((upper - dq).min()), float((dq - lower).min()))
        return qdot, IKStatus.LIMITED if slack <= 1e-9 else IKStatus.OK


CONTROLLERS: dict[str, type[DiffIKController]] = {
    c.name: c for c in (QPController, PinvController, DLSController)
}


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
