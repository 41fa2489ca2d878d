"""An arm and a gripper prepared for composition: what they are, and the physics they get.

:func:`prepare_arm` finds the arm's joints (the hinge and slide joints on the chain from its
root body to the flange), checks the description's per-joint data against them and gives every
arm joint one position actuator; :func:`prepare_gripper` finds the gripper's root body and
actuators and couples independent fingers. Both apply :mod:`pickplace.robot.physics`. What
cannot be repaired raises :class:`~pickplace.errors.RobotError` naming the description file,
the field and the element.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from pickplace.errors import RobotError
from pickplace.robot.compiled import compile_cached
from pickplace.robot.description import (
    ArmDescription,
    GripperDescription,
    RobotDescription,
    check_per_joint,
    check_speed_limits,
)
from pickplace.robot.mjcf import Part
from pickplace.robot.physics import (
    ARM_KP,
    GRIPPER_SATURATION_STROKE,
    ActuatorKind,
    Coupling,
    arm_min_armature,
    classify_actuators,
    couple_fingers,
    motor_to_position,
    name_unnamed_geoms,
    raise_armature,
    set_gravcomp,
    set_gripper_joint_minimums,
    set_robot_contacts,
    unique_name,
)

_HINGE_SLIDE = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
_JOINT_KIND = {
    int(mujoco.mjtJoint.mjJNT_FREE): "free",
    int(mujoco.mjtJoint.mjJNT_BALL): "ball",
    int(mujoco.mjtJoint.mjJNT_HINGE): "hinge",
    int(mujoco.mjtJoint.mjJNT_SLIDE): "slide",
}


def _compile(spec: mujoco.MjSpec, part: Part, step: str, *fields: object) -> mujoco.MjModel:
    """Compile a part's spec, or load the model a process compiled before (:mod:`compiled`).

    Args:
        spec: The part's spec, edited by this module from ``part``'s document.
        part: The part.
        step: Which edit of the spec this is (each compiled model is kept under its own key).
        fields: The description's fields the edits so far depended on.
    """

    def compile_now(s: mujoco.MjSpec) -> mujoco.MjModel:
        try:
            return s.compile()
        except ValueError as exc:
            raise part.error(f"MuJoCo cannot compile it: {' '.join(str(exc).split())}") from exc

    built_from = hashlib.sha256(repr((step, part.xml, fields)).encode()).hexdigest()
    return compile_cached(spec, built_from, compile_now)


def _name(model: mujoco.MjModel, obj: mujoco.mjtObj, i: int) -> str:
    return mujoco.mj_id2name(model, obj, i) or f"#{i}"


@dataclass(frozen=True)
class PreparedArm:
    """The arm part, ready to attach.

    Attributes:
        spec: Its spec with position actuators, gravity compensation and contact bits.
        joints: Arm joint names, root to flange.
        actuators: The position actuator of each arm joint, same order.
        flange_body: Body the gripper is attached to.
        flange_pos: Flange position in that body's frame [m].
        flange_quat: Flange orientation (wxyz) in that body's frame.
        repairs: What was changed, one line each.
        lowest_z: Lowest point [m] along the world's z, relative to the arm's root frame
            turned by ``[arm] base_quat``, of the collision geoms that move with a joint but
            whose height no joint changes (below the first joint that is not a vertical
            hinge): what stands closest to the floor whatever the posture; inf if none.
        lowest_geom: The geom with that point ("" if none).
    """

    spec: mujoco.MjSpec
    joints: tuple[str, ...]
    actuators: tuple[str, ...]
    flange_body: str
    flange_pos: np.ndarray
    flange_quat: np.ndarray
    repairs: tuple[str, ...]
    lowest_z: float = np.inf
    lowest_geom: str = ""


DEFAULT_FLANGE_SITE = "attachment_site"
"""The flange when the description names none: this site (MuJoCo Menagerie's convention for
where a tool goes), else the last body of the arm's chain."""


def _children(model: mujoco.MjModel) -> dict[int, list[int]]:
    out: dict[int, list[int]] = {}
    for b in range(1, model.nbody):
        out.setdefault(int(model.body_parentid[b]), []).append(b)
    return out


def _subtree_joints(model: mujoco.MjModel, children: dict[int, list[int]]) -> np.ndarray:
    """Number of joints of each body and every body below it."""
    count = model.body_jntnum.astype(int).copy()
    for b in range(model.nbody - 1, 0, -1):  # children come after their parents
        count[model.body_parentid[b]] += count[b]
    return count


def _chain_end(model: mujoco.MjModel) -> int:
    """The arm's last body: from the file's root body down the branch that carries the arm.

    A body with one child continues to it. Where the chain branches, it continues to the
    child that has more joints below it than all the other children together (the arm, not a
    head on one joint or a camera mount on none); where no child does (a hand's fingers,
    alike), the chain ends at the body it branches from.
    """
    children = _children(model)
    roots = children.get(0, [])
    if len(roots) != 1:
        return -1
    below = _subtree_joints(model, children)
    b = roots[0]
    while kids := children.get(b, []):
        if len(kids) == 1:
            b = kids[0]
            continue
        main = max(kids, key=lambda k: below[k])
        if below[main] <= sum(below[k] for k in kids) - below[main]:
            break
        b = main
    return b


def _leaf_bodies(model: mujoco.MjModel) -> list[str]:
    """Bodies without children: the candidate flange bodies, in file order."""
    children = _children(model)
    return [
        _name(model, mujoco.mjtObj.mjOBJ_BODY, b)
        for b in range(1, model.nbody)
        if b not in children
    ]


def _flange(
    model: mujoco.MjModel, arm: ArmDescription, part: Part, src: str
) -> tuple[int, np.ndarray, np.ndarray, str]:
    """Body of the flange, the flange's pose in it (a site's, or the body's own frame), and
    what was chosen in words when the description names no flange (else "")."""
    name = arm.flange
    chosen = ""
    if name is None:
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, DEFAULT_FLANGE_SITE) >= 0:
            name = DEFAULT_FLANGE_SITE
            chosen = f"site '{name}'"
        else:
            end = _chain_end(model)
            if end <= 0:
                raise RobotError(
                    f"{src}: [arm] flange: missing, and '{part.path}' has no site "
                    f"'{DEFAULT_FLANGE_SITE}' and no single chain of bodies; valid: "
                    f"{_flange_choices(model)}"
                )
            name = _name(model, mujoco.mjtObj.mjOBJ_BODY, end)
            chosen = f"body '{name}', the chain's last"
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
    if site >= 0:
        body = int(model.site_bodyid[site])
        return body, model.site_pos[site].copy(), model.site_quat[site].copy(), chosen
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    if body > 0:
        return body, np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), chosen
    raise RobotError(
        f"{src}: [arm] flange: '{name}' is no body or site of '{part.path}'; valid: "
        f"{_flange_choices(model)}"
    )


def _flange_choices(model: mujoco.MjModel) -> str:
    """The flange candidates in words: every named site, and the last bodies of the chain."""
    sites = [
        n
        for s in range(model.nsite)
        if (n := mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SITE, s))
    ]
    return (
        f"a site ({', '.join(sites) or 'none'}) or a body, e.g. the last of the chain "
        f"({', '.join(_leaf_bodies(model)) or 'none'})"
    )


def _hand_below(
    model: mujoco.MjModel,
    flange_body: int,
    chain: list[int],
    joint_ids: list[int],
    part: Part,
    src: str,
) -> None:
    """Refuse an arm file that carries a hand: jointed bodies below the flange, off the chain.

    The message names those bodies and, if the file's folder has one, the arm-only file: an
    MJCF file there whose joints are exactly the chain's.
    """
    on_chain = set(chain)
    below: list[int] = []
    stack = list(_children(model).get(flange_body, []))
    while stack:
        b = stack.pop()
        below.append(b)
        stack.extend(_children(model).get(b, []))
    hand = sorted(b for b in below if model.body_jntnum[b] > 0 and b not in on_chain)
    if not hand:
        return
    bodies = ", ".join(_name(model, mujoco.mjtObj.mjOBJ_BODY, b) for b in hand)
    joints = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joint_ids}
    arm_only = _arm_only_files(part.path, joints)
    hint = (
        f"the arm-only file beside it ({', '.join(arm_only)}) as [arm] mjcf, and the "
        f"hand's own file as [gripper] mjcf"
        if arm_only
        else "an arm file without the hand as [arm] mjcf, and the hand's own file as [gripper] mjcf"
    )
    flange = _name(model, mujoco.mjtObj.mjOBJ_BODY, flange_body)
    raise RobotError(
        f"{src}: [arm] mjcf: '{part.path.name}' already has a gripper below the flange "
        f"'{flange}' (jointed bodies {bodies}); valid: {hint}"
    )


def _arm_only_files(path: Path, joints: set[str | None]) -> list[str]:
    """MJCF files in ``path``'s folder whose named joints are exactly ``joints``."""
    out = []
    for other in sorted(path.parent.glob("*.xml")):
        if other.resolve() == path.resolve():
            continue
        try:
            root = ET.parse(other).getroot()
        except (OSError, ET.ParseError):
            continue
        names = {j.get("name") for j in root.iter("joint") if j.get("name")}
        if root.tag == "mujoco" and names == joints:
            out.append(other.name)
    return out


_VERTICAL = 1.0 - 1e-9


def _lowest_swivel_point(model: mujoco.MjModel, base_quat: np.ndarray) -> tuple[float, str]:
    """See :attr:`PreparedArm.lowest_z`: (height [m], geom name) at the file's own posture."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    flat = np.zeros(9)
    mujoco.mju_quat2Mat(flat, base_quat)
    R0 = flat.reshape(3, 3)
    level = np.zeros(model.nbody, dtype=bool)  # no joint above it changes its height
    moves = np.zeros(model.nbody, dtype=bool)  # some joint above it moves it
    level[0] = True
    for b in range(1, model.nbody):  # parents come before their children
        parent = int(model.body_parentid[b])
        level[b], moves[b] = level[parent], moves[parent]
        for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b]):
            moves[b] = True
            vertical = abs(float((R0 @ data.xaxis[j])[2])) >= _VERTICAL
            if int(model.jnt_type[j]) != int(mujoco.mjtJoint.mjJNT_HINGE) or not vertical:
                level[b] = False
    lowest, name = np.inf, ""
    for g in range(model.ngeom):
        b = int(model.geom_bodyid[g])
        if not (level[b] and moves[b]) or (
            model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0
        ):
            continue
        R = R0 @ data.geom_xmat[g].reshape(3, 3)
        p = R0 @ data.geom_xpos[g]
        mesh = int(model.geom_dataid[g])
        if int(model.geom_type[g]) == int(mujoco.mjtGeom.mjGEOM_MESH) and mesh >= 0:
            adr, num = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
            z = float(np.min(model.mesh_vert[adr : adr + num] @ R[2]) + p[2])
        else:
            c, h = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
            z = float(p[2] + R[2] @ c - np.abs(R[2]) @ h)
        if z < lowest:
            lowest, name = z, _name(model, mujoco.mjtObj.mjOBJ_GEOM, g)
    return lowest, name


def _chain_joints(model: mujoco.MjModel, flange_body: int, part: Part, src: str) -> list[int]:
    chain = []
    b = flange_body
    while b > 0:
        chain.append(b)
        b = int(model.body_parentid[b])
    chain.reverse()
    joints: list[int] = []
    for body in chain:
        for j in range(model.body_jntadr[body], model.body_jntadr[body] + model.body_jntnum[body]):
            if int(model.jnt_type[j]) not in _HINGE_SLIDE:
                raise RobotError(
                    f"{src}: [arm] flange: joint '{_name(model, mujoco.mjtObj.mjOBJ_JOINT, j)}' "
                    f"on the chain to the flange is a {_JOINT_KIND[int(model.jnt_type[j])]} joint; "
                    f"valid: hinge or slide joints only (the arm's root is fixed to the world)"
                )
            if not mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j):
                raise RobotError(
                    f"{src}: [arm] mjcf: joint #{len(joints) + 1} on the chain to the flange "
                    f"(body '{_name(model, mujoco.mjtObj.mjOBJ_BODY, body)}') has no name; "
                    f"valid: every arm joint named"
                )
            joints.append(j)
    if not joints:
        root = _name(model, mujoco.mjtObj.mjOBJ_BODY, chain[0]) if chain else "world"
        flange = _name(model, mujoco.mjtObj.mjOBJ_BODY, flange_body)
        raise RobotError(
            f"{src}: [arm] flange: no hinge or slide joint on the chain from the root body "
            f"'{root}' to '{flange}' in '{part.path}'; valid: a flange below the arm's joints"
        )
    return joints


def _narrow_to_control_range(
    spec: mujoco.MjSpec, model: mujoco.MjModel, joint: int, actuator: int, name: str
) -> tuple[str, tuple[float, float]] | None:
    """Give an arm joint its position actuator's control range where that is narrower than
    the joint's range (or the joint has none): what was done and the new range [rad or m],
    or None if nothing changed.

    MuJoCo clamps the control, so the joint's target (control over gear) never leaves that
    range: Menagerie's Gen3 drives its unlimited joints with ±2.8973 rad. As a joint range
    every model of the robot (the IK's, the planner's, the simulation's) keeps to it.
    """
    if not model.actuator_ctrllimited[actuator]:
        return None
    ends = model.actuator_ctrlrange[actuator] / model.actuator_gear[actuator, 0]
    lo, hi = model.jnt_range[joint] if model.jnt_limited[joint] else (-np.inf, np.inf)
    new_lo, new_hi = max(float(lo), float(ends.min())), min(float(hi), float(ends.max()))
    if (new_lo, new_hi) == (lo, hi):
        return None
    element = spec.joint(name)
    element.limited = mujoco.mjtLimited.mjLIMITED_TRUE
    hinge = model.jnt_type[joint] == mujoco.mjtJoint.mjJNT_HINGE
    scale = 180.0 / np.pi if hinge and spec.compiler.degree else 1.0
    element.range = [new_lo * scale, new_hi * scale]
    text = (
        f"arm joint '{name}' range narrowed to its actuator's control range "
        f"[{new_lo:g}, {new_hi:g}] (the target is clamped to it)"
    )
    return text, (new_lo, new_hi)


def prepare_arm(part: Part, desc: RobotDescription, timestep: float) -> PreparedArm:
    """Find the arm's joints and give each one position actuator.

    Motors on arm joints become position actuators (:data:`~pickplace.robot.physics.ARM_KP`,
    critical damping, the motor's torque limit); unactuated arm joints get one (force
    unbounded unless the joint has an actuator force range); position actuators are kept.
    Armature is raised to what the gain needs at ``timestep``. Bodies get gravity compensation,
    collision geoms the robot's contact bits.

    Raises:
        RobotError: The flange is not a body or site; no hinge or slide joint lies on the chain
            to it; speed, acceleration limits or home do not match the joints; an arm joint is
            driven by something other than one motor or position actuator.
    """
    src = str(desc.source)
    spec = part.new_spec()
    repairs: list[str] = []
    if named := name_unnamed_geoms(spec):
        repairs.append(f"{named} unnamed geoms named by body and index (body/geom[k])")
    model = _compile(spec, part, "arm: geoms named")
    flange_body, flange_pos, flange_quat, chosen = _flange(model, desc.arm, part, src)
    if chosen:
        repairs.append(f"no [arm] flange given: the {chosen}")
    joint_ids = _chain_joints(model, flange_body, part, src)
    chain = []
    b = flange_body
    while b > 0:
        chain.append(b)
        b = int(model.body_parentid[b])
    _hand_below(model, flange_body, chain, joint_ids, part, src)
    names = tuple(_name(model, mujoco.mjtObj.mjOBJ_JOINT, j) for j in joint_ids)
    check_speed_limits(desc.source, desc.arm.speed_limits, names)
    if desc.arm.accel_limits is not None:
        check_per_joint(desc.source, "[arm] accel_limits", desc.arm.accel_limits, names, "rad/s²")
    if desc.arm.home is not None:
        check_per_joint(desc.source, "[arm] home", desc.arm.home, names, "rad")
    ranges = {
        j: (tuple(model.jnt_range[j]) if model.jnt_limited[j] else (-np.inf, np.inf))
        for j in joint_ids
    }

    kinds = classify_actuators(model)
    by_joint: dict[int, list[ActuatorKind]] = {}
    for a in kinds:
        if a.joint >= 0:
            by_joint.setdefault(a.joint, []).append(a)
    act_names: list[str] = []
    existing = {a.name for a in spec.actuators}
    for j, name in zip(joint_ids, names, strict=True):
        acts = by_joint.get(j, [])
        rng = tuple(model.jnt_range[j]) if model.jnt_limited[j] else None
        if len(acts) > 1:
            raise RobotError(
                f"{src}: [arm] mjcf: arm joint '{name}' is driven by {len(acts)} actuators "
                f"({', '.join(a.name or '#' + str(a.index) for a in acts)}); valid: one"
            )
        if not acts:
            actuator = spec.add_actuator(name=unique_name(existing, name))
            existing.add(actuator.name)
            actuator.trntype = mujoco.mjtTrn.mjTRN_JOINT
            actuator.target = name
            limit = np.inf
            if model.jnt_actfrclimited[j]:
                limit = float(np.max(np.abs(model.jnt_actfrcrange[j])))
            motor_to_position(actuator, ARM_KP, limit, rng)
            repairs.append(f"arm joint '{name}' had no actuator: position actuator added")
            act_names.append(actuator.name)
            kp = ARM_KP
        else:
            a = acts[0]
            actuator = spec.actuators[a.index]
            if not a.name:
                actuator.name = unique_name(existing, name)
                existing.add(actuator.name)
            if a.kind == "motor":
                motor_to_position(actuator, ARM_KP, a.force_limit, rng)
                repairs.append(
                    f"arm motor '{actuator.name}' replaced by a position actuator (kp "
                    f"{ARM_KP:g}, force range ±{a.force_limit:g})"
                )
                kp = ARM_KP
            elif a.kind == "position":
                kp = float(model.actuator_gainprm[a.index, 0])
                if narrowed := _narrow_to_control_range(spec, model, j, a.index, name):
                    repairs.append(narrowed[0])
                    ranges[j] = narrowed[1]
            else:
                raise RobotError(
                    f"{src}: [arm] mjcf: actuator '{actuator.name}' on arm joint '{name}' is "
                    f"not a motor or a position actuator (ctrl = joint target); valid: "
                    f"<motor> or <position>"
                )
            act_names.append(actuator.name)
        joint = spec.joint(name)
        before = float(joint.armature)
        raise_armature(joint, arm_min_armature(kp, timestep))
        if joint.armature > before:
            repairs.append(f"arm joint '{name}' armature {before:g} → {joint.armature:g}")
    for j, name, q in zip(joint_ids, names, desc.arm.home or (), strict=False):
        lo, hi = ranges[j]
        if not lo <= q <= hi:
            raise RobotError(
                f"{src}: [arm] home: {name} = {q:g} is outside its range; valid: [{lo:g}, {hi:g}]"
            )
    lowest, lowest_geom = _lowest_swivel_point(model, np.array(desc.arm.base_quat))
    set_gravcomp(spec)
    set_robot_contacts(spec)
    return PreparedArm(
        spec=spec,
        joints=names,
        actuators=tuple(act_names),
        flange_body=_name(model, mujoco.mjtObj.mjOBJ_BODY, flange_body),
        flange_pos=flange_pos,
        flange_quat=flange_quat,
        repairs=tuple(repairs),
        lowest_z=lowest,
        lowest_geom=lowest_geom,
    )


@dataclass(frozen=True)
class PreparedGripper:
    """The gripper part, ready to calibrate and attach.

    Attributes:
        spec: Its spec (copy before editing) with position actuators, coupled fingers,
            joint minimums, gravity compensation and contact bits.
        root_body: Its root body (the frame mount_pos/quat and the tool point refer to).
        actuators: Its actuators after coupling, in spec order.
        file_actuators: The file's actuators, in file order (overrides refer to these).
        coupling: How independent fingers were coupled, or None.
        ctrl_ranges: Control range of each actuator in ``actuators``, shape (n, 2).
        repairs: What was changed, one line each.
    """

    spec: mujoco.MjSpec
    root_body: str
    actuators: tuple[str, ...]
    file_actuators: tuple[str, ...]
    coupling: Coupling | None
    ctrl_ranges: np.ndarray
    repairs: tuple[str, ...]

    def commands_from_file(self, values: tuple[float, ...], field: str, src: str) -> np.ndarray:
        """Map an override command given per file actuator to the prepared actuators."""
        if len(values) != len(self.file_actuators):
            raise RobotError(
                f"{src}: [gripper] {field}: has {len(values)} values; valid: "
                f"{len(self.file_actuators)}, one per actuator ({', '.join(self.file_actuators)})"
            )
        by_name = dict(zip(self.file_actuators, values, strict=True))
        out = []
        for name in self.actuators:
            if self.coupling is not None and name == self.coupling.actuator:
                pair = np.array([by_name[n] for n in self.coupling.replaced])
                out.append(self.coupling.tendon_command(pair))
            else:
                out.append(by_name[name])
        return np.array(out)


def _finger_span(model: mujoco.MjModel, data: mujoco.MjData, root: int) -> float:
    """Mean distance of moving collision geoms from the root's z axis [m] (opening proxy)."""
    mujoco.mj_kinematics(model, data)
    R = data.xmat[root].reshape(3, 3)
    p = (data.geom_xpos - data.xpos[root]) @ R
    moving = model.body_weldid[model.geom_bodyid] != model.body_weldid[root]
    collide = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    sel = moving & collide
    return float(np.mean(np.hypot(p[sel, 0], p[sel, 1]))) if sel.any() else 0.0


def _open_end(
    model: mujoco.MjModel, joint: int, root: int, lo: float, hi: float
) -> tuple[float, float]:
    """(open, closed) targets of a finger joint: the end that takes its geoms farther out."""
    data = mujoco.MjData(model)
    adr = model.jnt_qposadr[joint]
    data.qpos[adr] = lo
    span_lo = _finger_span(model, data, root)
    data.qpos[adr] = hi
    span_hi = _finger_span(model, data, root)
    return (hi, lo) if span_hi >= span_lo else (lo, hi)


def prepare_gripper(part: Part, desc: RobotDescription) -> PreparedGripper:
    """Find the gripper's root and actuators, make them position-controlled, couple fingers.

    Raises:
        RobotError: The file has not exactly one root body, no actuator, an actuator that is
            neither a motor nor position-like, or one without a control range.
    """
    src = str(desc.source)
    grip: GripperDescription = desc.gripper
    spec = part.new_spec()
    repairs: list[str] = []
    if named := name_unnamed_geoms(spec):
        repairs.append(f"{named} unnamed geoms named by body and index (body/geom[k])")
    roots = [b.name for b in spec.worldbody.bodies]
    if len(roots) != 1 or not roots[0]:
        raise RobotError(
            f"{src}: [gripper] mjcf: '{part.path}' has {len(roots)} root bodies "
            f"({', '.join(repr(r) for r in roots)}); valid: one named root body"
        )
    existing = {a.name for a in spec.actuators if a.name}
    for i, actuator in enumerate(spec.actuators):
        if not actuator.name:
            actuator.name = unique_name(existing, f"actuator{i}")
            existing.add(actuator.name)
    file_actuators = tuple(a.name for a in spec.actuators)
    model = _compile(spec, part, "gripper: as read")
    if model.nu == 0:
        raise RobotError(
            f"{src}: [gripper] mjcf: '{part.path}' has no actuator; valid: a motor, position "
            f"or general (affine) actuator that opens and closes the fingers"
        )
    kinds = classify_actuators(model)
    for a in kinds:
        actuator = spec.actuators[a.index]
        if a.kind == "motor":
            if a.joint < 0 or not model.jnt_limited[a.joint]:
                raise RobotError(
                    f"{src}: [gripper] mjcf: motor '{a.name}' does not drive one limited joint; "
                    f"valid: a motor on a finger joint with a range, or a position actuator"
                )
            lo, hi = model.jnt_range[a.joint]
            if not np.isfinite(a.force_limit):
                raise RobotError(
                    f"{src}: [gripper] mjcf: motor '{a.name}' has no force limit (ctrlrange or "
                    f"forcerange); valid: a bounded motor"
                )
            kp = a.force_limit / (GRIPPER_SATURATION_STROKE * (hi - lo))
            motor_to_position(actuator, kp, a.force_limit, (float(lo), float(hi)))
            repairs.append(
                f"gripper motor '{a.name}' replaced by a position actuator (kp {kp:.4g})"
            )
        elif a.kind == "other":
            raise RobotError(
                f"{src}: [gripper] mjcf: actuator '{a.name}' is neither a motor nor position-"
                f"like (gain > 0, affine bias pulling to the command); valid: <motor>, "
                f"<position> or <general> with biastype affine"
            )
    model = _compile(spec, part, "gripper: position actuators")
    kinds = classify_actuators(model)
    for a in kinds:
        if not model.actuator_ctrllimited[a.index]:
            raise RobotError(
                f"{src}: [gripper] mjcf: actuator '{a.name}' has no ctrlrange; valid: a "
                f"ctrlrange, or [gripper] open_command and closed_command"
            )
    root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, roots[0])
    coupling = None
    linked = {
        frozenset((int(model.eq_obj1id[e]), int(model.eq_obj2id[e])))
        for e in range(model.neq)
        if model.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT
    }
    if (
        grip.couple_fingers
        and len(kinds) == 2
        and all(a.kind == "position" and a.joint >= 0 for a in kinds)
        and kinds[0].joint != kinds[1].joint
        and frozenset((kinds[0].joint, kinds[1].joint)) not in linked
    ):
        ends = [_open_end(model, a.joint, root, *model.actuator_ctrlrange[a.index]) for a in kinds]
        coupling = couple_fingers(
            spec,
            model,
            (kinds[0], kinds[1]),
            (ends[0][0], ends[1][0]),
            (ends[0][1], ends[1][1]),
        )
        repairs.append(
            f"independent fingers '{coupling.joints[0]}' and '{coupling.joints[1]}' coupled "
            f"(tendon '{coupling.tendon}', joint equality, actuator '{coupling.actuator}')"
        )
    set_gripper_joint_minimums(spec)
    set_gravcomp(spec)
    set_robot_contacts(spec)
    model = _compile(spec, part, "gripper: prepared", grip.couple_fingers)
    actuators = tuple(
        mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, i) for i in range(model.nu)
    )
    return PreparedGripper(
        spec=spec,
        root_body=roots[0],
        actuators=actuators,
        file_actuators=file_actuators,
        coupling=coupling,
        ctrl_ranges=model.actuator_ctrlrange.copy(),
        repairs=tuple(repairs),
    )
