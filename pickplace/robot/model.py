"""The resolved robot: everything the pipeline needs of an arm and its gripper in a compiled
model (ids, limits, home posture, gripper commands and measurements, the pad gap maths),
sized from the loaded robot itself; and the composition that holds it with its model."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property

import mujoco
import numpy as np

from pickplace.errors import RobotError
from pickplace.geometry import rotate_by_quat
from pickplace.robot.calibration import GripperCalibration
from pickplace.robot.compiled import compile_cached
from pickplace.robot.description import RobotDescription


@dataclass(frozen=True)
class Robot:
    """Everything the pipeline needs about the composed robot, resolved from the model.

    Ids and addresses refer to the composed model. Arm arrays have one entry per arm joint
    (``n = len(arm_joint_names)``, root to flange).

    Attributes:
        name: The description's name.
        description: The description it was built from.
        arm_joint_names: Arm joints in the scene (prefixed), root to flange.
        arm_joint_ids: Their joint ids.
        arm_qpos_adr: Their qpos addresses.
        arm_dof_adr: Their dof (qvel) addresses.
        q_min: Lower limits [rad or m] (a joint's range is narrowed to its position
            actuator's control range by the loader); -inf for continuous (unlimited) joints.
        q_max: Upper limits; +inf for continuous joints.
        continuous: True for arm joints limited by neither their range nor their actuator's
            control range.
        v_max: Speed limits [rad/s or m/s] from the description.
        a_max: Acceleration limits [rad/s² or m/s²] from the description, or None.
        arm_actuator_ids: The position actuator of each arm joint.
        q_home: Home posture: the description's, or found by IK (``home_source``).
        home_source: ``"description"`` or ``"ik"``.
        home_candidates: The description's home, or every distinct IK home, best joint margin
            first (``q_home`` is the first; the scene loader may choose another).
        gripper_actuator_ids: The gripper's actuators (order of command vectors).
        gripper_joint_ids: The gripper's hinge and slide joints (order of
            :meth:`qpos_for_width`).
        gripper_kind: What the gripper is, in words (fingers, joints, actuators, coupling).
        open_command: Command that opens the gripper fully.
        closed_command: Command that closes it (full squeeze on an object).
        open_width: Gap between the pads at the open command [m].
        closed_width: Gap at the closed command with nothing between the fingers [m].
        squeeze_force: Squeeze per jaw to judge a grasp against [N]: the description's
            ``grip_force``, else the measured squeeze.
        measured_squeeze_force: Mean pad normal force on a brick-sized box, closed [N].
        gap_on_brick: Pad gap while squeezing a brick-sized box [m].
        pad_geom_ids: Pad geoms of the +y ("left") and -y ("right") sides of the tool frame.
        pad_body_ids: Bodies of those pads (same structure).
        pad_faces_body: Per side, each pad's face point in its body's frame [m], shape (k, 3).
        pad_force_sensor_ids: Per side, the pad–brick contact sensors (one per pad).
        pad_force_sensor_adr: Their sensordata addresses.
        pad_force_slots: Contacts each pad sensor reports.
        tool_site_name: The calibrated tool site (z approach, y closing axis).
        tool_site_id: Its id.
        tool_body_id: Its body (the gripper's root).
        y_tool_body: The tool's y axis in that body's frame.
        robot_body_ids: Every body of the arm and gripper.
        robot_geom_ids: Every collision geom of the arm and gripper.
        gripper_geom_ids: The gripper's collision geoms.
        footprint_G: The gripper's collision geoms at the open width as boxes in the tool
            frame, shape (k, 2, 3) [min corner, max corner] [m].
        p_W_base: Anchor of the first arm joint at the model's reference posture [m].
        flange_body_id: The arm body the gripper is mounted on.
        home_key_id: The ``home`` keyframe.
        home_width: Gripper gap of the ``home`` keyframe [m].
        calibration: The gripper calibration (gap map, pads, tool point, footprint).
        repairs: What composition changed in the files, one line each.
    """

    name: str
    description: RobotDescription = field(repr=False)
    arm_joint_names: tuple[str, ...]
    arm_joint_ids: np.ndarray
    arm_qpos_adr: np.ndarray
    arm_dof_adr: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    continuous: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray | None
    arm_actuator_ids: np.ndarray
    q_home: np.ndarray
    home_source: str
    home_candidates: tuple[np.ndarray, ...]
    gripper_actuator_ids: np.ndarray
    gripper_joint_ids: np.ndarray
    gripper_kind: str
    open_command: np.ndarray
    closed_command: np.ndarray
    open_width: float
    closed_width: float
    squeeze_force: float
    measured_squeeze_force: float
    gap_on_brick: float
    pad_geom_ids: tuple[np.ndarray, np.ndarray]
    pad_body_ids: tuple[np.ndarray, np.ndarray]
    pad_faces_body: tuple[np.ndarray, np.ndarray]
    pad_force_sensor_ids: tuple[np.ndarray, np.ndarray]
    pad_force_sensor_adr: tuple[np.ndarray, np.ndarray]
    pad_force_slots: int
    tool_site_name: str
    tool_site_id: int
    tool_body_id: int
    y_tool_body: np.ndarray
    robot_body_ids: np.ndarray
    robot_geom_ids: np.ndarray
    gripper_geom_ids: np.ndarray
    footprint_G: np.ndarray
    p_W_base: np.ndarray
    flange_body_id: int
    home_key_id: int
    home_width: float
    calibration: GripperCalibration = field(repr=False)
    repairs: tuple[str, ...] = ()

    @property
    def n_joints(self) -> int:
        """Number of arm joints."""
        return len(self.arm_joint_names)

    def write_home(self, model: mujoco.MjModel, q_home: np.ndarray, width: float) -> None:
        """Write the home posture ``q_home`` [rad] and the gripper at gap ``width`` [m] into
        ``model``'s ``home`` keyframe (positions and the commands that hold them; the rest of
        the keyframe is ``qpos0`` and no command). The one writer of the keyframe: the
        composition, the scene and the loader's home choice all call it."""
        key = self.home_key_id
        model.key_qpos[key, self.arm_qpos_adr] = q_home
        model.key_qpos[key, model.jnt_qposadr[self.gripper_joint_ids]] = self.qpos_for_width(width)
        model.key_ctrl[key, self.arm_actuator_ids] = q_home
        model.key_ctrl[key, self.gripper_actuator_ids] = self.ctrl_for_width(width)

    def ctrl_for_width(self, width: float) -> np.ndarray:
        """Gripper command that holds the free fingers at gap ``width`` [m].

        At or below the calibration's ``squeeze_width`` it is the closed command (full squeeze
        on an object).
        """
        return self.calibration.ctrl_for_width(width)

    def ctrl_for_widths(self, widths: np.ndarray) -> np.ndarray:
        """:meth:`ctrl_for_width` of every entry of ``widths`` (k,) [m], shape (k, actuators)."""
        cal = self.calibration
        s = cal.fractions_for_widths(np.asarray(widths, dtype=float))
        return cal.closed_command + s[:, None] * (cal.open_command - cal.closed_command)

    def qpos_for_width(self, width: float) -> np.ndarray:
        """Positions of the gripper joints (:attr:`gripper_joint_ids`) of the free fingers at
        gap ``width`` [m] (clipped to the calibrated range): what a kinematic copy sets."""
        return self.calibration.qpos_for_width(width)

    def gap_from_body_poses(
        self, body_pos: np.ndarray, body_quat: np.ndarray, y_W: np.ndarray | None = None
    ) -> np.ndarray:
        """Pad gap [m] from body poses, vectorised over leading axes.

        Args:
            body_pos: Body positions in world, shape (..., nbody, 3) (``data.xpos``).
            body_quat: Body orientations wxyz, shape (..., nbody, 4) (``data.xquat``).
            y_W: The tool's y axis in world, shape (..., 3), if known (the tool site's rotation
                matrix's second column); else computed from the tool body's orientation.

        Returns:
            Shape (...): the innermost +y pad face minus the innermost -y pad face, along the
            tool's y axis.
        """
        if y_W is None:
            y_W = rotate_by_quat(body_quat[..., self.tool_body_id, :], self.y_tool_body)
        bodies = np.concatenate(self.pad_body_ids)
        faces = np.concatenate(self.pad_faces_body)
        p = body_pos[..., bodies, :] + rotate_by_quat(
            body_quat[..., bodies, :], faces
        )  # both sides
        along = np.einsum("...ki,...i->...k", p, y_W)
        k = len(self.pad_body_ids[0])
        return along[..., :k].min(axis=-1) - along[..., k:].max(axis=-1)

    def gap(self, data: mujoco.MjData) -> float:
        """Current pad gap [m]."""
        return float(self.gap_from_body_poses(data.xpos, data.xquat))

    def pad_friction(self, model: mujoco.MjModel) -> float:
        """The sliding friction coefficient [-] where the pads touch what they hold: the pads'
        own, the least of them (they have contact priority), as ``model`` has it now."""
        pads = np.concatenate(self.pad_geom_ids)
        return float(model.geom_friction[pads, 0].min())

    def pad_normal_forces(self, sensordata: np.ndarray) -> np.ndarray:
        """Normal force [N] of the brick on the +y and -y pads, shape (..., 2), from
        sensordata of shape (..., nsensordata)."""
        n = 4 * self.pad_force_slots
        out = []
        for adrs in self.pad_force_sensor_adr:
            total = 0.0
            for a in adrs:
                rows = sensordata[..., a : a + n].reshape(*sensordata.shape[:-1], -1, 4)
                total = total + rows[..., 1].sum(axis=-1)
            out.append(total)
        return np.stack(out, axis=-1)

    def make_data(self, model: mujoco.MjModel) -> mujoco.MjData:
        """Fresh MjData of ``model`` reset to the home keyframe."""
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, self.home_key_id)
        mujoco.mj_forward(model, data)
        return data


@dataclass(frozen=True)
class Composition:
    """A composed scene: its spec (for derived models), the compiled model, the robot.

    Attributes:
        spec: The composed spec (compiled into ``model``).
        model: The compiled scene.
        robot: The robot resolved in it.
        arm_spec: A copy of ``spec`` taken before it was compiled, which :attr:`arm_model`
            strips: removing an element from the copy of a compiled spec costs 10–30 ms with
            a published robot's meshes (measured, Menagerie iiwa14 + 2F-85), from a copy of an
            uncompiled one about 1 ms.
        cache_key: What ``spec`` was built from, digested: models derived from it are kept on
            disk under keys made from it (:mod:`pickplace.robot.compiled`); None: not kept.
    """

    spec: mujoco.MjSpec
    model: mujoco.MjModel
    robot: Robot
    arm_spec: mujoco.MjSpec
    cache_key: str | None = None

    def derived_key(self, *what: object) -> str | None:
        """The key of a model compiled from an edited copy of :attr:`spec`, where ``what``
        says everything the edits depended on (None if the spec is not kept)."""
        if self.cache_key is None:
            return None
        return hashlib.sha256(repr((self.cache_key, what)).encode()).hexdigest()

    @cached_property
    def arm_model(self) -> mujoco.MjModel:
        """The scene compiled with only the arm joints left (nq = nv = n), for the IK.

        Gripper joints, the brick's free joint and everything that refers to joints
        (actuators, tendons, equalities, sensors, keyframes) are removed; bodies, sites and
        geometry are unchanged, so the tool site's forward kinematics equal the simulation's.
        """
        spec = self.arm_spec  # stripped once: the property is cached
        for collection in ("actuators", "tendons", "equalities", "sensors", "keys", "pairs"):
            for element in list(getattr(spec, collection)):
                spec.delete(element)
        for element in list(spec.excludes):
            spec.delete(element)
        keep = set(self.robot.arm_joint_names)
        for joint in list(spec.joints):
            if joint.name not in keep:
                spec.delete(joint)
        model = compile_cached(
            spec,
            self.derived_key("arm joints only", self.robot.arm_joint_names),
            mujoco.MjSpec.compile,
        )
        order = tuple(
            mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(model.njnt)
        )
        if order != self.robot.arm_joint_names:
            raise RobotError(
                f"arm joints {order} are not in the order {self.robot.arm_joint_names}"
            )
        return model
