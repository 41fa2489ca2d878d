"""The physics every composed robot gets, whatever its files say.

Published arm and gripper files leave to their project's code what our grasp needs
(``docs/physics-notes.md``: "Arm and gripper files from elsewhere", "Grasp physics"). These
edits, made on a part's ``MjSpec`` before it is composed, supply it:

* torque ``motor`` actuators become position actuators (``kp``, critical damping) whose force
  range is the motor's torque limit and whose control range is the joint's range;
* gravity compensation on every robot body (``gravcomp = 1``);
* a minimum armature on arm joints, so that the position gain is stable at the timestep, and a
  minimum armature and damping on gripper joints (a published linkage gripper flops without);
* robot collision geoms on contact bits of their own: :data:`ROBOT_CONTYPE` and
  :data:`ROBOT_CONAFFINITY` make robot geoms collide with the world's (contype and
  conaffinity 1, MuJoCo's default) but not with each other;
* independently actuated fingers coupled by a fixed tendon and a joint equality, driven by one
  position actuator on the tendon (independent force-limited fingers let a held brick float
  14 mm along the closing axis; coupled 0.01 mm);
* stiff pads: ``priority 1``, ``solref (2·timestep, 1)``, ``solimp (0.95, 0.99, 0.001)``.

Functions take the part's spec and, where they must classify actuators or joints, the part
compiled on its own (element order in ``spec.actuators`` equals actuator ids).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

ROBOT_CONTYPE = 1 << 1
"""contype of every robot collision geom (bit 1): world geoms (conaffinity 1) do not see it..."""

ROBOT_CONAFFINITY = 1 << 0
"""... but robot geoms accept world geoms (contype 1): robot–world contacts, no self-collision."""

ARM_KP = 2000.0
"""Position gain of an arm actuator made from a motor [N·m/rad] (docs/physics-notes.md: 500 to
10,000 all picked; 2000 with critical damping is what the bundled arms use)."""

ARM_STABILITY = 0.5
"""Largest ω·dt of a position-controlled arm joint on its armature alone: armature is raised to
at least ``kp · (dt / ARM_STABILITY)²`` (explicit stiffness is stable below ω·dt = 2)."""

GRIPPER_SATURATION_STROKE = 0.1
"""A gripper motor becomes a position actuator whose force saturates once its target lies this
fraction of the joint's stroke past the finger: ``kp = force limit / (0.1 · stroke)``."""

GRIPPER_MIN_ARMATURE = 0.002
"""Minimum armature of a gripper joint [kg·m² or kg] (docs/physics-notes.md)."""

GRIPPER_MIN_DAMPING = 0.05
"""Minimum damping of a gripper joint [N·m·s/rad or N·s/m] (docs/physics-notes.md)."""

PAD_SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)
"""solimp of stiff pads (docs/physics-notes.md, "Grasp physics")."""

COUPLING_SOLREF = (0.005, 1.0)
COUPLING_SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)


@dataclass(frozen=True)
class ActuatorKind:
    """How an actuator of a part drives what.

    Attributes:
        index: Actuator id in the part.
        name: Its name.
        kind: ``"motor"`` (torque), ``"position"`` (ctrl = target of its transmission) or
            ``"position-like"`` (affine bias pulling to a scaled ctrl, e.g. a 0–255 command).
        joint: Joint id it drives, or -1 (tendon or other transmission).
        force_limit: Largest |force| it can apply [N or N·m], inf when unbounded.
    """

    index: int
    name: str
    kind: str
    joint: int
    force_limit: float


def classify_actuators(model: mujoco.MjModel) -> list[ActuatorKind]:
    """Classify every actuator of a compiled part.

    Returns:
        One entry per actuator; ``kind`` is ``"other"`` for what is none of the three.
    """
    out = []
    trn = mujoco.mjtTrn
    for i in range(model.nu):
        gaintype, biastype = model.actuator_gaintype[i], model.actuator_biastype[i]
        gain, bias = model.actuator_gainprm[i], model.actuator_biasprm[i]
        fixed = gaintype == mujoco.mjtGain.mjGAIN_FIXED
        kind = "other"
        if fixed and biastype == mujoco.mjtBias.mjBIAS_NONE and model.actuator_dyntype[i] == 0:
            kind = "motor"
        elif fixed and biastype == mujoco.mjtBias.mjBIAS_AFFINE and gain[0] > 0 and bias[1] < 0:
            exact = abs(gain[0] + bias[1]) <= 1e-9 * gain[0] and bias[0] == 0
            kind = "position" if exact else "position-like"
        gear = abs(float(model.actuator_gear[i, 0]))
        limit = np.inf
        if kind == "motor" and model.actuator_ctrllimited[i]:
            limit = gear * float(np.max(np.abs(model.actuator_ctrlrange[i])))
        if model.actuator_forcelimited[i]:
            limit = min(limit, float(np.max(np.abs(model.actuator_forcerange[i]))))
        joint = (
            int(model.actuator_trnid[i, 0]) if model.actuator_trntype[i] == trn.mjTRN_JOINT else -1
        )
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, i) or ""
        out.append(ActuatorKind(i, name, kind, joint, limit))
    return out


def motor_to_position(
    actuator: mujoco.MjsActuator,
    kp: float,
    force_limit: float,
    joint_range: tuple[float, float] | None,
) -> None:
    """Turn a torque motor into a critically damped position actuator on the same joint.

    Args:
        actuator: The motor's spec element (its transmission is kept, its gear set to 1).
        kp: Position gain [N·m/rad or N/m].
        force_limit: The motor's torque limit [N·m or N]; inf leaves the force unbounded.
        joint_range: The joint's range (becomes the control range), or None if unlimited.
    """
    actuator.set_to_position(kp=kp, dampratio=1.0)
    actuator.gear = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    if np.isfinite(force_limit):
        actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.forcerange = [-force_limit, force_limit]
    else:
        actuator.forcelimited = mujoco.mjtLimited.mjLIMITED_FALSE
    if joint_range is not None:
        actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        actuator.ctrlrange = list(joint_range)
    else:
        actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE


def set_gravcomp(spec: mujoco.MjSpec) -> None:
    """Gravity compensation on every body of a part (``gravcomp = 1``)."""
    for body in spec.bodies:
        if body.name != "world":
            body.gravcomp = 1.0


def set_robot_contacts(spec: mujoco.MjSpec) -> list[str]:
    """Put every collision geom of a part on the robot's contact bits.

    Returns:
        Names of the geoms that collide (``contype`` or ``conaffinity`` was non-zero).
    """
    names = []
    for geom in spec.geoms:
        if geom.contype != 0 or geom.conaffinity != 0:
            geom.contype = ROBOT_CONTYPE
            geom.conaffinity = ROBOT_CONAFFINITY
            names.append(geom.name)
    return names


def raise_armature(joint: mujoco.MjsJoint, minimum: float) -> None:
    """Armature of ``joint`` at least ``minimum``."""
    joint.armature = max(float(joint.armature), minimum)


def arm_min_armature(kp: float, timestep: float) -> float:
    """Armature that keeps a position gain ``kp`` stable at ``timestep`` on its own [kg·m²]."""
    return kp * (timestep / ARM_STABILITY) ** 2


def set_gripper_joint_minimums(spec: mujoco.MjSpec) -> None:
    """Armature and damping of every hinge and slide joint of a gripper at least the minimums."""
    for joint in spec.joints:
        if joint.type in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
            raise_armature(joint, GRIPPER_MIN_ARMATURE)
            damping = np.array(joint.damping, dtype=float)  # MuJoCo 4: [linear, ...] terms
            damping[0] = max(damping[0], GRIPPER_MIN_DAMPING)
            joint.damping = damping


def set_stiff_pad(geom: mujoco.MjsGeom, timestep: float) -> None:
    """Stiff priority contact on a pad geom (docs/physics-notes.md); its friction is kept."""
    geom.priority = 1
    geom.solref = [2.0 * timestep, 1.0]
    geom.solimp = list(PAD_SOLIMP)


def stiff_pad_model(model: mujoco.MjModel, geom_ids: list[int]) -> None:
    """The same as :func:`set_stiff_pad`, on a compiled model (calibration uses it)."""
    for g in geom_ids:
        model.geom_priority[g] = 1
        model.geom_solref[g] = [2.0 * model.opt.timestep, 1.0]
        model.geom_solimp[g] = PAD_SOLIMP


@dataclass(frozen=True)
class Coupling:
    """Two independently actuated fingers made one: ``q2 = offset + ratio · q1``.

    Attributes:
        joints: The two finger joints.
        signs: +1 where a joint's q grows as the finger opens, -1 otherwise.
        tendon: Name of the fixed tendon ``L = ½ (s1 q1 + s2 q2)``.
        actuator: Name of the position actuator on the tendon.
        replaced: Names of the two actuators it replaces, in file order.
    """

    joints: tuple[str, str]
    signs: tuple[float, float]
    tendon: str
    actuator: str
    replaced: tuple[str, str]

    def tendon_command(self, commands: np.ndarray) -> float:
        """The tendon length that corresponds to the two replaced actuators' targets."""
        return 0.5 * (self.signs[0] * float(commands[0]) + self.signs[1] * float(commands[1]))


def name_unnamed_geoms(spec: mujoco.MjSpec) -> int:
    """Name every unnamed geom of a part by its body and index: ``hand/geom[3]``.

    The index counts the body's geoms in file order from 0, visual ones included, so the
    name can be found by reading the file; an unnamed body is ``body[k]`` (k its index in
    the file, the world 0). Names, not ids, are what calibration, messages, overrides
    (``[gripper] pads``) and recordings use.

    Returns:
        How many geoms were named.
    """
    existing = {g.name for g in spec.geoms if g.name}
    named = 0
    for k, body in enumerate(spec.bodies):
        label = body.name or f"body[{k}]"
        for i, geom in enumerate(body.geoms):
            if not geom.name:
                geom.name = unique_name(existing, f"{label}/geom[{i}]")
                existing.add(geom.name)
                named += 1
    return named


def scale_squeeze(spec: mujoco.MjSpec, ratio: float) -> None:
    """Scale a gripper's squeeze by ``ratio``, as ``--vary grip_force`` scales a scene's.

    Every actuator's force range × ratio; when ratio > 1 its position gain and bias × ratio
    too and its damping × √ratio (the same damping ratio), so that a gripper whose squeeze is
    set by its gain (a position actuator closing on a box it cannot reach) squeezes harder.
    """
    gain = max(1.0, ratio)
    for actuator in spec.actuators:
        actuator.forcerange = [float(v) * ratio for v in actuator.forcerange]
        gainprm = np.array(actuator.gainprm, dtype=float)
        biasprm = np.array(actuator.biasprm, dtype=float)
        gainprm[0] *= gain
        biasprm[1] *= gain
        biasprm[2] *= np.sqrt(gain)
        actuator.gainprm = gainprm
        actuator.biasprm = biasprm


def unique_name(existing: set[str], name: str) -> str:
    """``name``, or ``name_2``, ``name_3`` … : the first not in ``existing``."""
    candidate, k = name, 1
    while candidate in existing:
        k += 1
        candidate = f"{name}_{k}"
    return candidate


def couple_fingers(
    spec: mujoco.MjSpec,
    model: mujoco.MjModel,
    actuators: tuple[ActuatorKind, ActuatorKind],
    open_targets: tuple[float, float],
    closed_targets: tuple[float, float],
) -> Coupling:
    """Replace two position actuators on two finger joints by one on a coupling tendon.

    The joint equality maps closed to closed and open to open; the tendon's actuator has
    twice the fingers' mean gain (each finger sees half the tendon force) and a force range of
    the sum of their force limits, so each jaw squeezes with its own limit.

    Args:
        spec: The gripper's spec (edited).
        model: The gripper compiled on its own.
        actuators: The two position actuators, each on its own joint.
        open_targets: Each actuator's target when open.
        closed_targets: Each actuator's target when closed.
    """
    j1, j2 = (a.joint for a in actuators)
    n1 = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j1)
    n2 = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j2)
    (o1, o2), (c1, c2) = open_targets, closed_targets
    s1, s2 = float(np.sign(o1 - c1)), float(np.sign(o2 - c2))
    ratio = (o2 - c2) / (o1 - c1)
    offset = c2 - ratio * c1

    names = {t.name for t in spec.tendons}
    tendon = spec.add_tendon(name=unique_name(names, "finger_coupling"))
    tendon.wrap_joint(n1, 0.5 * s1)
    tendon.wrap_joint(n2, 0.5 * s2)

    eq = spec.add_equality()
    eq.type = mujoco.mjtEq.mjEQ_JOINT
    eq.name1, eq.name2 = n1, n2
    data = np.zeros(len(eq.data))
    data[0], data[1] = offset, ratio
    eq.data = data
    eq.solref = list(COUPLING_SOLREF)
    eq.solimp = list(COUPLING_SOLIMP)

    kp = float(np.mean([model.actuator_gainprm[a.index, 0] for a in actuators]))
    force = sum(a.force_limit for a in actuators)
    lengths = sorted((0.5 * (s1 * c1 + s2 * c2), 0.5 * (s1 * o1 + s2 * o2)))
    replaced = (actuators[0].name, actuators[1].name)
    for a in actuators:
        spec.delete(spec.actuators[[x.name for x in spec.actuators].index(a.name)])
    act_names = {a.name for a in spec.actuators}
    act = spec.add_actuator(name=unique_name(act_names, "fingers"))
    act.trntype = mujoco.mjtTrn.mjTRN_TENDON
    act.target = tendon.name
    act.set_to_position(kp=2.0 * kp, dampratio=1.0)
    act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
    act.ctrlrange = lengths
    if np.isfinite(force):
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-force, force]
    return Coupling(
        joints=(n1, n2),
        signs=(s1, s2),
        tendon=tendon.name,
        actuator=act.name,
        replaced=replaced,
    )
