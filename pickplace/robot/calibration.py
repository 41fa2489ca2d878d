"""Calibrate a gripper in simulation: commands, gap map, pads, tool point, footprint, force.

Nothing about the gripper is hand-entered. The prepared gripper (``pickplace.robot.parts``) is
mounted on a slide joint — a jointed mount, not welded to the world, which would exempt the
hand from MuJoCo's parent–child contact filter — in a world without gravity, with two static
boxes (mocap bodies, put in place when needed): the brick and a thin probe; the scene's
timestep and solver options. Then:

1. **Open and closed commands**: each actuator is driven to both ends of its control range; the
   end that takes the fingers' collision geoms farther from the root's z axis opens.
2. **Closing axis y**: the principal direction of the fingers' displacement from open to
   closed (after removing their common motion); **approach z**: from the root body's origin
   towards the fingers, orthogonal to y; x = y × z. Axes within 1e-9 of the root's are snapped.
   Fingers moving along -y when closing are the **+y side**.
3. **Pads and tool point**: a probe — a slab of the brick's width and length, 5 mm high — is
   put between the fingertips (the geoms that travel farthest, each side), flush with their
   distal end, and the gripper closes on it; the geoms touching it on both sides are the first
   pads (if a side touches nothing the probe steps towards the palm, over the brick's height).
   The tool point is midway between the two sides' pad face centres (each pad's local bounding
   box face towards the other side). Then, as a grasp holds the brick, a box of the brick's
   size centred on the tool point is squeezed; the geoms carrying at least
   :data:`PAD_FORCE_SHARE` of a side's force are the pads, and the tool point moves midway
   between them, until the pads stay the same. (Only a brick-sized box finds the innermost
   geoms over the brick's height, e.g. pads set back from a longer finger; only the probe
   keeps a box at the fingertips off what protrudes inwards above the pads, e.g. knuckles.)
4. **Squeeze force**: with stiff pads (docs/physics-notes.md), closed on the brick-sized box at the
   tool point: the pads' normal forces per side, the gap between their faces, and any other
   gripper geom touching the box (reported).
5. **Gap map**: the command is swept from closed to open without the box; at each step the gap
   between the innermost pad faces along y is measured. It must grow monotonically and end
   wider than the brick.
6. **Footprint**: every collision geom of the gripper, at the open command, as a box in the
   tool frame (its local bounding box, rotated into G and bounded again).
7. **Action times**: the commanded gap ramped as a plan ramps it (linearly in gap, through the
   gap map), from open to closed on the brick-sized box and from closed on it to open. The
   **close time** is the shortest ramp by whose end the grip has been steady — both sides at
   :data:`GRIP_FORCE_SHARE` of their squeeze, the gap still to :data:`STEADY_GAP_SPEED` — for
   :data:`ACTION_HOLD`; the **open time** the shortest ramp that has the pads clear the brick
   by :data:`RELEASE_CLEARANCE` a side as long before its end. The ramps span the gap a grasp
   opens to (:data:`~pickplace.planning.grasp.GRASP_OPEN_WIDTH`, or less when the gripper opens
   less);
   both times are multiples of :data:`ACTION_RESOLUTION`, found by doubling and bisection.

Each stage waits until the gripper is at rest: its velocities below :data:`SETTLED_SPEED`, or
below :data:`STILL_MOVING` at :data:`REST_TIME` (contacts and soft loop constraints of a linkage
creep at ~1e-5 for seconds; that is at rest). A gripper still moving then is judged by what a
grasp needs: the stage ends once the fingers' geoms and each side's force on a box change by less
than their tolerances over :data:`SETTLE_WINDOW` — :data:`POSITION_TOLERANCE` of the gripper's
stroke, :data:`FORCE_TOLERANCE` of the force — so that a linkage whose followers creep while
its pads stand still (Robotiq's 2F-85 squeezing a box: 0.004–0.009 rad/s) is measured; not
steady by :data:`MAX_SETTLE_TIME` is an error naming what still changes and by how much.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import mujoco
import numpy as np

from pickplace.errors import RobotError
from pickplace.robot.description import TcpOverride
from pickplace.robot.parts import PreparedGripper
from pickplace.robot.physics import stiff_pad_model

GRIPPER_PREFIX = "gripper/"
"""Prefix of the gripper's element names, in calibration and in the composed scene."""

SETTLED_SPEED = 1e-6
"""A stage ends when every joint moves slower than this [m/s or rad/s] ..."""

MIN_SETTLE_TIME = 0.06
"""... after at least this long [s] ..."""

REST_TIME = 1.5
"""... or at this time [s] every joint slower than ..."""

STILL_MOVING = 1e-3
"""... this [m/s or rad/s]; else, from then on, the stage ends when what a grasp needs is steady:"""

SETTLE_WINDOW = 0.05
"""Steady means changed by less than the tolerances over this long [s] (whole 20 ms chunks):"""

POSITION_TOLERANCE = 1e-3
"""Each finger geom's centre by this share of the gripper's stroke (of its size before the
stroke is measured): 0.085 mm per 50 ms for an 85 mm stroke ..."""

FORCE_TOLERANCE = 0.01
"""... and each side's normal force on a box by this share of it ..."""

FORCE_FLOOR = 1e-3
"""... or by this [N], whichever is more (a side that touches nothing)."""

MAX_SETTLE_TIME = 8.0
"""A stage not steady after this long [s] fails the calibration."""

PAD_ITERATIONS = 4
"""Rounds of "close on a brick centred between the pads found so far" before pads are final."""

PAD_FORCE_SHARE = 0.05
"""A geom is a pad if it carries at least this share of its side's squeeze (a graze is not)."""

PROBE_HEIGHT = 0.005
"""Height [m] of the probe: a brick-wide slab put at the fingertips to find the pads."""

SWEEP_POINTS = 11
"""Commands of the gap map, evenly spaced from closed to open."""

MOVING = 1e-4
"""A geom that moves more than this [m] between open and closed is a finger geom."""

FINGERTIP_TRAVEL = 0.5
"""Finger geoms that travel at least this fraction of their side's largest travel are
fingertip candidates (where the box is put)."""

ACTION_HOLD = 0.03
"""A gripper action is done this long before its ramp ends [s]: the grip is steady for three
control ticks at 100 Hz before a plan lifts, the pads clear before it retreats."""

ACTION_RESOLUTION = 0.025
"""Action times are whole multiples of this [s] ..."""

MAX_ACTION_TIME = 2.0
"""... of at most this [s]: a gripper slower than that fails the calibration."""

GRIP_FORCE_SHARE = 0.95
"""The grip is steady when each side presses with this share of its settled squeeze ..."""

STEADY_GAP_SPEED = 1e-3
"""... and the pad gap changes slower than this [m/s] (0.05 mm in 50 ms)."""

RELEASE_CLEARANCE = 0.005
"""The pads have let go when each clears the brick by this [m] (or by half of what the
gripper opens beyond the brick, when that is less)."""

TIP_CLEARANCE = 0.008
"""The open fingers' farthest point along the approach stays this far [m] short of the far face
of a brick centred on the tool point: the pre-flight's 5 mm clearance from the floor the brick
rests on, plus the 3 mm by which the tool arrives off the planned pick at full speed
(:data:`PAD_CLEARANCE`) ..."""

GRIP_TIP_CLEARANCE = 0.005
"""... and the gripping fingers' this far [m]: the pre-flight's 5 mm alone, the tool having
stopped at the pick before the fingers close."""

PALM_CLEARANCE = 0.003
"""A brick centred on the tool point clears the open gripper by this [m] when the tool point
had to move away from the palm: the same 3 mm by which the tool arrives off the pick."""

DEPTH_STEPS = 20
"""Bisection steps of the tool point's move away from the palm (0.1 mm over 10 cm)."""

_SNAP = 1e-9


class _Problem(Exception):  # noqa: N818 - internal, always converted to RobotError
    """A calibration failure, located by the description field it concerns."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field = field
        self.message = message


@dataclass(frozen=True)
class CalibrationOptions:
    """The scene's physics, used for calibration (timestep [s], integrator, cone, impratio)."""

    timestep: float = 0.002
    integrator: int = int(mujoco.mjtIntegrator.mjINT_IMPLICITFAST)
    cone: int = int(mujoco.mjtCone.mjCONE_ELLIPTIC)
    impratio: float = 10.0
    noslip_iterations: int = 0


@dataclass(frozen=True)
class GripperCalibration:
    """What calibration measured. Names are the gripper file's (no prefix).

    Attributes:
        root_body: The gripper's root body; positions and rotations below are in its frame B
            unless they say G (the tool frame).
        actuators: The gripper's actuators (after coupling), order of the command vectors.
        joints: The gripper's hinge and slide joints, order of ``sweep_qpos``.
        open_command: Command that opens the fingers fully.
        closed_command: Command that closes them fully (and squeezes).
        sweep_fraction: Fractions s of the sweep, command = closed + s (open - closed).
        sweep_gap: Gap between the pad faces at each fraction [m] (non-decreasing).
        sweep_qpos: Gripper joint positions at each fraction.
        open_width: Gap at the open command [m].
        closed_width: Gap at the closed command, fingers free [m] (may be < 0 when fingers
            pass each other: robot geoms do not collide with each other).
        squeeze_width: Commanded gaps at or below this [m] give the closed command:
            ``closed_width``, or the brick's width for a gripper that the gap map alone does
            not close in time (see :func:`calibrate_gripper`).
        pads: Pad geoms of the +y side and of the -y side.
        pad_faces: Per side, each pad's face point in the pad geom's own frame [m].
        pos_BG: Tool point in B [m].
        quat_BG: Tool frame orientation in B (wxyz): z approach, y closing axis.
        squeeze_force: Mean normal force of the two sides on the box, closed command [N].
        squeeze_per_side: The +y and -y sides' normal forces [N].
        gap_on_brick: Gap between the pad faces while squeezing the box [m].
        other_contacts: Gripper geoms other than the pads that touch the squeezed box (they
            take part of the squeeze; empty for a clean parallel grip).
        footprint_geoms: Collision geoms of the gripper, order of ``footprint_G``.
        footprint_G: Their boxes in the tool frame at the open command, (k, 2, 3) as
            [min corner, max corner] [m].
        brick_half_extents: Half sizes of the box used (brick length, width, height) [m].
        close_time: Shortest ramp of the commanded gap from the grasp's open width to closed
            whose last :data:`ACTION_HOLD` the grip on the box is steady [s].
        open_time: Shortest ramp from closed on the box to the grasp's open width that has
            the pads let go of it :data:`ACTION_HOLD` before its end [s].
        sim_time: Simulated time the calibration took [s].
    """

    root_body: str
    actuators: tuple[str, ...]
    joints: tuple[str, ...]
    open_command: np.ndarray
    closed_command: np.ndarray
    sweep_fraction: np.ndarray
    sweep_gap: np.ndarray
    sweep_qpos: np.ndarray
    open_width: float
    closed_width: float
    squeeze_width: float
    pads: tuple[tuple[str, ...], tuple[str, ...]]
    pad_faces: tuple[np.ndarray, np.ndarray]
    pos_BG: np.ndarray
    quat_BG: np.ndarray
    squeeze_force: float
    squeeze_per_side: np.ndarray
    gap_on_brick: float
    other_contacts: tuple[str, ...]
    footprint_geoms: tuple[str, ...]
    footprint_G: np.ndarray
    brick_half_extents: np.ndarray
    close_time: float
    open_time: float
    sim_time: float

    def fraction_for_width(self, width: float) -> float:
        """Sweep fraction whose free gap is ``width`` [m], clipped to [0, 1]; 0 (closed) at
        or below ``squeeze_width``."""
        return float(self.fractions_for_widths(np.array([width]))[0])

    def fractions_for_widths(self, widths: np.ndarray) -> np.ndarray:
        """:meth:`fraction_for_width` of every entry of ``widths`` [m]."""
        s = np.clip(np.interp(widths, self.sweep_gap, self.sweep_fraction), 0.0, 1.0)
        return np.where(np.asarray(widths) <= self.squeeze_width, 0.0, s)

    def command(self, fraction: float) -> np.ndarray:
        """Command at sweep fraction ``fraction`` (0 closed, 1 open)."""
        return self.closed_command + fraction * (self.open_command - self.closed_command)

    def ctrl_for_width(self, width: float) -> np.ndarray:
        """Command that holds the free fingers at gap ``width`` [m].

        Widths at or below ``squeeze_width`` give the closed command (full squeeze on an
        object); at or above ``open_width`` the open command.
        """
        return self.command(self.fraction_for_width(width))

    def qpos_for_width(self, width: float) -> np.ndarray:
        """Gripper joint positions (order of ``joints``) of the free fingers at ``width``."""
        s = float(np.clip(np.interp(width, self.sweep_gap, self.sweep_fraction), 0.0, 1.0))
        return np.array(
            [np.interp(s, self.sweep_fraction, q) for q in self.sweep_qpos.T], dtype=float
        )


class _Rig:
    """The calibration model: gripper on a slide mount, a mocap box, no gravity."""

    def __init__(
        self,
        gripper: PreparedGripper,
        options: CalibrationOptions,
        half: np.ndarray,
        friction: np.ndarray,
    ) -> None:
        spec = mujoco.MjSpec()
        spec.compiler.degree = False
        opt = spec.option
        opt.timestep = options.timestep
        opt.integrator = options.integrator
        opt.cone = options.cone
        opt.impratio = options.impratio
        opt.noslip_iterations = options.noslip_iterations
        opt.gravity = [0.0, 0.0, 0.0]
        mount = spec.worldbody.add_body(name="calibration_mount")
        mount.explicitinertial = True
        mount.mass = 1.0
        mount.inertia = [1e-2, 1e-2, 1e-2]
        mount.add_joint(
            name="calibration_mount",
            type=mujoco.mjtJoint.mjJNT_SLIDE,
            axis=[0.0, 0.0, 1.0],
            stiffness=1e5,
            damping=2e3,
        )
        spec.attach(gripper.spec.copy(), prefix=GRIPPER_PREFIX, frame=mount.add_frame())
        probe = np.array([half[0], half[1], 0.5 * PROBE_HEIGHT])
        for k, (name, size) in enumerate(
            (("calibration_brick", half), ("calibration_probe", probe))
        ):
            box = spec.worldbody.add_body(name=name, mocap=True, pos=[0.0, 0.0, -10.0 - k])
            box.add_geom(
                name=name,
                type=mujoco.mjtGeom.mjGEOM_BOX,
                size=list(size),
                contype=1,
                conaffinity=1,
                friction=list(friction),
            )
        try:
            self.model = spec.compile()
        except ValueError as exc:
            detail = " ".join(str(exc).split())
            raise _Problem(
                "mjcf",
                f"does not compile on the calibration mount: {detail}; valid: a gripper that "
                f"compiles attached to a jointed body",
            ) from exc
        m = self.model
        self.data = mujoco.MjData(m)
        obj = mujoco.mjtObj
        self.root = mujoco.mj_name2id(m, obj.mjOBJ_BODY, GRIPPER_PREFIX + gripper.root_body)
        self.box_geoms = {
            which: mujoco.mj_name2id(m, obj.mjOBJ_GEOM, f"calibration_{which}")
            for which in ("brick", "probe")
        }
        self.acts = np.array(
            [
                mujoco.mj_name2id(m, obj.mjOBJ_ACTUATOR, GRIPPER_PREFIX + a)
                for a in gripper.actuators
            ]
        )
        weld = m.body_weldid
        gripper_body = np.array(
            [
                (mujoco.mj_id2name(m, obj.mjOBJ_BODY, b) or "").startswith(GRIPPER_PREFIX)
                for b in range(m.nbody)
            ]
        )
        collide = (m.geom_contype != 0) | (m.geom_conaffinity != 0)
        self.geoms = np.flatnonzero(gripper_body[m.geom_bodyid] & collide)
        self.moving_body = gripper_body & (weld != weld[self.root])
        self.joints = np.array(
            [
                j
                for j in range(m.njnt)
                if gripper_body[m.jnt_bodyid[j]]
                and int(m.jnt_type[j])
                in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
            ],
            dtype=int,
        )
        self.sim_time = 0.0
        mujoco.mj_forward(m, self.data)
        self.finger_geoms = self.geoms[self.moving_body[m.geom_bodyid[self.geoms]]]
        reach = (
            np.linalg.norm(self.geom_centres_B()[self.geoms], axis=1) + m.geom_rbound[self.geoms]
        )
        self.scale = float(reach.max()) if reach.size else 0.1
        self.scale_label = f"size ({1000 * self.scale:.0f} mm)"
        self.placed: dict[str, bool] = {}
        self.sides: dict[int, int] = {}

    def set_stroke(self, stroke: float, sides: dict[int, int]) -> None:
        """The fingers' stroke [m] (scale of the position tolerance) and each finger geom's
        side (+1 / -1), once measured."""
        if stroke > 0.0:
            self.scale = stroke
            self.scale_label = f"stroke ({1000 * stroke:.1f} mm)"
        self.sides = dict(sides)

    def name(self, geom: int) -> str:
        full = mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_GEOM, geom) or f"#{geom}"
        return full.removeprefix(GRIPPER_PREFIX)

    def watched(self) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """What a grasp needs steady, its tolerances per :data:`SETTLE_WINDOW`, and labels.

        The centres of the fingers' collision geoms in B (tolerance
        :data:`POSITION_TOLERANCE` of :attr:`scale`: the gripper's stroke once known, its
        size before) and, while a box is placed, the normal force each side presses on it
        with (tolerance :data:`FORCE_TOLERANCE` of that force, at least
        :data:`FORCE_FLOOR`). Joint angles are not watched: a linkage's followers may creep
        while the fingers and the squeeze stand still.
        """
        centres = self.geom_centres_B()[self.finger_geoms].reshape(-1)
        values = [centres]
        tols = [np.full(centres.size, POSITION_TOLERANCE * self.scale)]
        labels = [f"{self.name(int(g))} position" for g in self.finger_geoms for _ in range(3)]
        for which in self.box_geoms:
            if not self.placed.get(which):
                continue
            forces = self.box_contacts(which)
            per_side = np.array(
                [
                    sum(f for g, f in forces.items() if self.sides.get(g, 1) == side)
                    for side in (1, -1)
                ]
            )
            values.append(per_side)
            tols.append(np.maximum(FORCE_TOLERANCE * np.abs(per_side), FORCE_FLOOR))
            labels += [f"force on the {which} (+y side)", f"force on the {which} (-y side)"]
        return np.concatenate(values), np.concatenate(tols), labels

    def settle(self, ctrl: np.ndarray, what: str) -> None:
        """Hold ``ctrl`` until the gripper is at rest, or what a grasp needs is steady.

        At rest: every joint slower than :data:`SETTLED_SPEED` after :data:`MIN_SETTLE_TIME`
        (or slower than :data:`STILL_MOVING` at :data:`REST_TIME`). From :data:`REST_TIME`
        on, steady is enough: :meth:`watched` changed by less than its tolerances over the
        last :data:`SETTLE_WINDOW`. Not steady by :data:`MAX_SETTLE_TIME` is an error
        naming what still changes.
        """
        m, d = self.model, self.data
        d.ctrl[self.acts] = ctrl
        chunk = max(1, round(0.02 / m.opt.timestep))
        window = max(1, math.ceil(SETTLE_WINDOW / (chunk * m.opt.timestep)))
        t0 = d.time
        history: list[np.ndarray] = []
        while True:
            mujoco.mj_step(m, d, nstep=chunk)
            if not np.all(np.isfinite(d.qvel)):
                raise _Problem(
                    "mjcf",
                    f"the gripper's simulation diverged while {what}; valid: a gripper stable "
                    f"at timestep {m.opt.timestep:g} s (check masses, armature, gains)",
                )
            elapsed = d.time - t0
            fastest = float(np.max(np.abs(d.qvel))) if d.qvel.size else 0.0
            if elapsed >= MIN_SETTLE_TIME and fastest < SETTLED_SPEED:
                break
            if elapsed < REST_TIME - 1e-9:
                continue
            if not history and fastest < STILL_MOVING:
                break
            values, tols, labels = self.watched()
            history.append(values)
            if len(history) <= window:
                continue
            change = np.abs(values - history[-1 - window])
            if np.all(change <= tols):
                break
            if elapsed >= MAX_SETTLE_TIME:
                k = int(np.argmax(change / tols))
                force = "force" in labels[k]
                unit, scale = ("N", 1.0) if force else ("mm", 1000.0)
                basis = (
                    f"{100 * FORCE_TOLERANCE:g} % of it"
                    if force
                    else f"{100 * POSITION_TOLERANCE:g} % of the gripper's {self.scale_label}"
                )
                raise _Problem(
                    "mjcf",
                    f"the gripper does not settle while {what}: after {MAX_SETTLE_TIME:g} s the "
                    f"{labels[k]} still changes by {scale * change[k]:.3g} {unit} per "
                    f"{1000 * window * chunk * m.opt.timestep:.0f} ms (tolerance "
                    f"{scale * tols[k]:.3g} {unit}, {basis}); valid: fingers and a squeeze that "
                    f"come to rest (damped finger joints), or set [gripper] closed_command to "
                    f"a gentler squeeze",
                )
        self.sim_time += d.time - t0

    def step(self, ctrl: np.ndarray) -> None:
        """One physics step at command ``ctrl``."""
        self.data.ctrl[self.acts] = ctrl
        mujoco.mj_step(self.model, self.data)
        self.sim_time += self.model.opt.timestep

    def state(self) -> np.ndarray:
        m, d = self.model, self.data
        full = np.empty(mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_INTEGRATION))
        mujoco.mj_getState(m, d, full, mujoco.mjtState.mjSTATE_INTEGRATION)
        return full

    def restore(self, state: np.ndarray) -> None:
        mujoco.mj_setState(self.model, self.data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
        mujoco.mj_forward(self.model, self.data)

    def root_pose(self) -> tuple[np.ndarray, np.ndarray]:
        d = self.data
        return d.xpos[self.root].copy(), d.xmat[self.root].reshape(3, 3).copy()

    def geom_centres_B(self) -> np.ndarray:
        p, R = self.root_pose()
        return (self.data.geom_xpos - p) @ R

    def geom_rot_B(self, g: int) -> np.ndarray:
        _, R = self.root_pose()
        return R.T @ self.data.geom_xmat[g].reshape(3, 3)

    def place_box(
        self, which: str | None, pos_B: np.ndarray | None = None, R_B: np.ndarray | None = None
    ) -> None:
        """Put the ``"brick"`` or ``"probe"`` box at a pose in B, the other far away."""
        m, d = self.model, self.data
        for k, (name, geom) in enumerate(self.box_geoms.items()):
            mocap = int(m.body_mocapid[m.geom_bodyid[geom]])
            self.placed[name] = name == which and pos_B is not None and R_B is not None
            if not self.placed[name]:
                d.mocap_pos[mocap] = [0.0, 0.0, -10.0 - k]
                continue
            p, R = self.root_pose()
            d.mocap_pos[mocap] = p + R @ pos_B
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, (R @ R_B).reshape(9))
            d.mocap_quat[mocap] = quat
        mujoco.mj_forward(m, d)

    def box_contacts(self, which: str) -> dict[int, float]:
        """Normal force on the ``which`` box from each gripper geom touching it [N]."""
        m, d = self.model, self.data
        box = self.box_geoms[which]
        forces: dict[int, float] = {}
        f6 = np.zeros(6)
        for i in range(d.ncon):
            c = d.contact[i]
            g1, g2 = int(c.geom1), int(c.geom2)
            if box not in (g1, g2):
                continue
            other = g2 if g1 == box else g1
            mujoco.mj_contactForce(m, d, i, f6)
            forces[other] = forces.get(other, 0.0) + float(f6[0])
        return forces


def _snap(v: np.ndarray) -> np.ndarray:
    out = v.copy()
    for k in range(3):
        if abs(abs(out[k]) - 1.0) < _SNAP:
            e = np.zeros(3)
            e[k] = math.copysign(1.0, out[k])
            return e
    out[np.abs(out) < _SNAP] = 0.0
    return out / np.linalg.norm(out)


def _span(rig: _Rig, geoms: np.ndarray) -> float:
    c = rig.geom_centres_B()[geoms]
    return float(np.mean(np.hypot(c[:, 0], c[:, 1])))


def _commands(rig: _Rig, gripper: PreparedGripper) -> tuple[np.ndarray, np.ndarray]:
    """(open, closed) commands: per actuator, the range end that spreads the fingers."""
    lo, hi = gripper.ctrl_ranges[:, 0].copy(), gripper.ctrl_ranges[:, 1].copy()
    mid = 0.5 * (lo + hi)
    moving = rig.geoms[rig.moving_body[rig.model.geom_bodyid[rig.geoms]]]
    if moving.size == 0:
        raise _Problem(
            "pads",
            "no pads found: no collision geom moves with a finger joint; valid: fingers with "
            "collision geoms (contype or conaffinity non-zero) on jointed bodies",
        )
    open_cmd, closed_cmd = mid.copy(), mid.copy()
    start = rig.state()
    for i in range(len(mid)):
        spans = []
        for end in (lo[i], hi[i]):
            rig.restore(start)
            u = mid.copy() if len(mid) > 1 else np.array([end])
            u[i] = end
            rig.settle(u, f"driving actuator '{gripper.actuators[i]}' to {end:g}")
            spans.append(_span(rig, moving))
        if abs(spans[1] - spans[0]) < MOVING:
            raise _Problem(
                "mjcf",
                f"actuator '{gripper.actuators[i]}' moves no finger over its ctrlrange "
                f"[{lo[i]:g}, {hi[i]:g}]; valid: actuators that open and close the fingers",
            )
        opens_high = spans[1] > spans[0]
        open_cmd[i], closed_cmd[i] = (hi[i], lo[i]) if opens_high else (lo[i], hi[i])
    rig.restore(start)
    return open_cmd, closed_cmd


@dataclass
class _Axes:
    R_BG: np.ndarray  # columns x, y, z of G in B
    side: dict[int, int]  # moving geom -> +1 (+y side) / -1
    travel: dict[int, float]  # |closing displacement along y| [m]


def _axes(rig: _Rig, c_open: np.ndarray, c_closed: np.ndarray, tcp: TcpOverride | None) -> _Axes:
    geoms = rig.geoms[rig.moving_body[rig.model.geom_bodyid[rig.geoms]]]
    delta = c_closed[geoms] - c_open[geoms]
    moved = np.linalg.norm(delta, axis=1) > MOVING
    geoms, delta = geoms[moved], delta[moved]
    if geoms.size < 2:
        raise _Problem(
            "pads",
            "no pads found: fewer than two finger collision geoms move when closing; valid: "
            "two fingers with collision geoms",
        )
    centred = delta - delta.mean(axis=0)
    _, sv, Vt = np.linalg.svd(centred)
    if sv[0] < MOVING:
        raise _Problem(
            "pads",
            "no pads found: all finger geoms move alike when the gripper closes (one moving "
            "jaw?); valid: two fingers closing towards each other",
        )
    y = Vt[0]
    for k in (1, 0, 2):
        if abs(y[k]) > 1e-6:
            y = y * math.copysign(1.0, y[k])
            break
    y = _snap(y)
    v = c_open[geoms].mean(axis=0)
    v = v - (v @ y) * y
    if np.linalg.norm(v) < 1e-3:
        v = np.array([0.0, 0.0, 1.0]) - y[2] * y
    z = _snap(v / np.linalg.norm(v))
    x = _snap(np.cross(y, z))
    z = np.cross(x, y)
    R_BG = np.column_stack([x, y, z])
    if tcp is not None and tcp.site is None:
        R_BG = np.zeros(9)
        mujoco.mju_quat2Mat(R_BG, np.array(tcp.quat))
        R_BG = R_BG.reshape(3, 3)
    y = R_BG[:, 1]
    along = (delta - delta.mean(axis=0)) @ y
    by_motion = {int(g): (1 if a < 0 else -1) for g, a in zip(geoms, along, strict=True)}
    travel = {int(g): abs(float(dv @ y)) for g, dv in zip(geoms, delta, strict=True)}
    # The geoms that travel farthest are sided by their motion; every other finger geom by
    # where it lies, beyond or short of the midplane between them: a linkage's knuckle that
    # swings outwards while its finger closes presses from the side it is on.
    top = max(travel.values())
    leaders = {g: s for g, s in by_motion.items() if travel[g] >= FINGERTIP_TRAVEL * top}
    side = dict(by_motion)
    if len(set(leaders.values())) == 2:
        where = {int(g): float(c @ y) for g, c in zip(geoms, c_open[geoms], strict=True)}
        mid = 0.5 * sum(
            float(np.mean([where[g] for g, s in leaders.items() if s == k])) for k in (1, -1)
        )
        side = {g: leaders.get(g, 1 if where[g] > mid else -1) for g in by_motion}
    if len(set(side.values())) < 2:
        raise _Problem(
            "pads",
            "no pads found: the fingers do not close towards each other; valid: two fingers "
            "closing along one axis",
        )
    return _Axes(R_BG, side, travel)


def _aabb_G(
    rig: _Rig, g: int, R_BG: np.ndarray, origin_B: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Centre and half sizes of geom ``g``'s local bounding box, as a box in G's axes."""
    m = rig.model
    c_local, h_local = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
    R_Bg = rig.geom_rot_B(g)
    centre_B = rig.geom_centres_B()[g] + R_Bg @ c_local
    R_Gg = R_BG.T @ R_Bg
    return R_BG.T @ (centre_B - origin_B), np.abs(R_Gg) @ h_local


def _probe_positions(rig: _Rig, axes: _Axes, half: np.ndarray) -> list[np.ndarray]:
    """Probe centres in B: between the fingertips, from their distal end towards the palm.

    The probe steps by its height from flush with the fingers' distal end (the nearer of the
    two sides' farthest geoms along the approach) over the brick's height, stopping short of
    the palm (geoms that do not move). At each step only the finger geoms level with the probe
    (overlapping its height and its length) bound it: the probe is centred between the two
    sides' innermost of them, and a step where they do not open wider than the brick (a
    knuckle nearer the palm, a finger's crossbar) or where one side has none is skipped.

    Raises:
        _Problem: No step has the fingers open wider than the brick.
    """
    R = axes.R_BG
    boxes = {g: _aabb_G(rig, g, R, np.zeros(3)) for g in axes.side}
    distal = min(
        max(c[2] + h[2] for g, (c, h) in boxes.items() if axes.side[g] == s) for s in (1, -1)
    )
    reach = distal - 2.0 * half[2]
    near_tip = {g: c for g, (c, h) in boxes.items() if c[2] + h[2] > reach}
    x_c = float(np.mean([c[0] for c in near_tip.values()]))
    y_c = 0.5 * sum(
        float(np.mean([c[1] for g, c in near_tip.items() if axes.side[g] == s] or [0.0]))
        for s in (1, -1)
    )
    palm = -np.inf
    for g in map(int, rig.geoms):
        if rig.moving_body[rig.model.geom_bodyid[g]]:
            continue
        c, h = _aabb_G(rig, g, R, np.zeros(3))
        if abs(c[0] - x_c) < h[0] + half[0] and abs(c[1] - y_c) < h[1] + half[1]:
            palm = max(palm, c[2] + h[2])
    out, widest = [], -np.inf
    z = distal - 0.5 * PROBE_HEIGHT
    while z >= reach and z - 0.5 * PROBE_HEIGHT > palm + 1e-3:
        level = [
            g
            for g, (c, h) in boxes.items()
            if abs(c[2] - z) < h[2] + 0.5 * PROBE_HEIGHT and abs(c[0] - x_c) < h[0] + half[0]
        ]
        inner_pos = min(
            (boxes[g][0][1] - boxes[g][1][1] for g in level if axes.side[g] == 1), default=np.inf
        )
        inner_neg = max(
            (boxes[g][0][1] + boxes[g][1][1] for g in level if axes.side[g] == -1), default=-np.inf
        )
        z_here, z = z, z - PROBE_HEIGHT
        if not (np.isfinite(inner_pos) and np.isfinite(inner_neg)):
            continue
        widest = max(widest, inner_pos - inner_neg)
        if inner_pos - inner_neg > 2.0 * half[1]:
            out.append(R @ np.array([x_c, 0.5 * (inner_pos + inner_neg), z_here]))
    if not out:
        opens = f"{1000 * widest:.1f} mm" if np.isfinite(widest) else "nothing facing each other"
        raise _Problem(
            "mjcf",
            f"the gripper cannot open wider than the brick: its fingertips open to {opens} "
            f"(the finger geoms facing each other within {2000 * half[2]:.0f} mm of their "
            f"distal end), the brick is {2000 * half[1]:.1f} mm wide; valid: a gripper that "
            f"opens wider than the brick",
        )
    return out


def _touching(
    rig: _Rig, axes: _Axes, which: str, among: set[int] | None = None, share: float = 1e-3
) -> tuple[list[int], list[int]]:
    """Finger geoms (of ``among``, if given) pressing on the ``which`` box, per side.

    A geom counts if its normal force is at least ``share`` of its side's total.
    """
    forces = rig.box_contacts(which)
    out: tuple[list[int], list[int]] = ([], [])
    for k, side in enumerate((1, -1)):
        mine = {
            g: f
            for g, f in forces.items()
            if axes.side.get(g) == side and (among is None or g in among)
        }
        total = sum(mine.values())
        out[k].extend(sorted(g for g, f in mine.items() if total > 0 and f >= share * total))
    return out


def _named_pads(
    rig: _Rig, axes: _Axes, names: tuple[tuple[str, ...], tuple[str, ...]]
) -> tuple[list[int], list[int]]:
    """Overridden pad names as geoms of the +y and -y sides."""
    fingers = ", ".join(sorted(rig.name(g) for g in axes.side))
    sides: dict[int, list[int]] = {1: [], -1: []}
    for group in names:
        ids = []
        for n in group:
            g = mujoco.mj_name2id(rig.model, mujoco.mjtObj.mjOBJ_GEOM, GRIPPER_PREFIX + n)
            if g < 0 or g not in axes.side:
                raise _Problem(
                    "pads", f"'{n}' is not a collision geom of a finger; valid: {fingers}"
                )
            ids.append(g)
        group_sides = {axes.side[g] for g in ids}
        if len(group_sides) != 1:
            raise _Problem("pads", f"{list(group)} lie on both fingers; valid: one list per finger")
        sides[group_sides.pop()] += ids
    if not sides[1] or not sides[-1]:
        raise _Problem("pads", "both lists are on the same finger; valid: one per finger")
    return sorted(sides[1]), sorted(sides[-1])


def _find_pads(
    rig: _Rig,
    axes: _Axes,
    open_state: np.ndarray,
    u_closed: np.ndarray,
    positions: list[np.ndarray],
    named: tuple[list[int], list[int]] | None,
) -> tuple[tuple[list[int], list[int]], np.ndarray]:
    """Close on the probe at each position until it touches pads on both sides.

    Returns:
        The pads of the +y and -y sides (the named ones, if given) and the probe position.
    """
    among = None if named is None else set(named[0] + named[1])
    seen: set[int] = set()
    for pos in positions:
        rig.restore(open_state)
        rig.place_box("probe", pos, axes.R_BG)
        if rig.box_contacts("probe"):
            raise _Problem(
                "mjcf",
                "the open gripper already touches a brick-wide probe between its fingertips; "
                "valid: a gripper that opens wider than the brick",
            )
        rig.settle(u_closed, "closing on a brick-wide probe")
        pos_pads, neg_pads = _touching(rig, axes, "probe", among)
        every = _touching(rig, axes, "probe")
        seen.update(every[0] + every[1])
        if pos_pads and neg_pads:
            return (named or (pos_pads, neg_pads)), pos
    found = ", ".join(sorted(rig.name(g) for g in seen)) or "nothing"
    fingers = ", ".join(sorted(rig.name(g) for g in axes.side))
    raise _Problem(
        "pads",
        f"no pads found: closing on a brick-wide probe between the fingertips, the fingers "
        f"touched it with {found}; valid: fingers whose collision geoms squeeze it from both "
        f"sides, or set pads = [[...], [...]] from {fingers}",
    )


def _support(m: mujoco.MjModel, g: int, u: np.ndarray) -> float:
    """Farthest extent [m] of geom ``g`` along the unit vector ``u`` of its own frame, from its
    origin: its vertices for a mesh (MuJoCo collides with their convex hull), else its local
    bounding box (exact for a box, an upper bound for a turned capsule or cylinder).

    A mesh's local frame is its principal axes, which need not be the gripper's: its bounding
    box's corner along a closing axis 19 degrees off the box's axes lies 11.6 mm inside the
    inner face of Menagerie's xArm hand fingers (measured), which made the pads 25.7 mm apart
    squeezing a 50 mm box."""
    mesh = int(m.geom_dataid[g])
    if int(m.geom_type[g]) == int(mujoco.mjtGeom.mjGEOM_MESH) and mesh >= 0:
        adr, num = m.mesh_vertadr[mesh], m.mesh_vertnum[mesh]
        return float(np.max(m.mesh_vert[adr : adr + num] @ u))
    c, h = m.geom_aabb[g, :3], m.geom_aabb[g, 3:]
    return float(c @ u + np.abs(u) @ h)


def _pad_faces(rig: _Rig, pads: list[int], inward_B: np.ndarray) -> np.ndarray:
    """Face point of each pad in its own geom frame: on the plane that bounds it towards
    ``inward_B`` (:func:`_support`), level with its bounding box's centre."""
    out = []
    for g in pads:
        u = rig.geom_rot_B(g).T @ inward_B
        c = rig.model.geom_aabb[g, :3]
        out.append(c + (_support(rig.model, g, u) - float(c @ u)) * u)
    return np.array(out)


def _faces_B(rig: _Rig, pads: list[int], faces: np.ndarray) -> np.ndarray:
    centres = rig.geom_centres_B()
    return np.array([centres[g] + rig.geom_rot_B(g) @ f for g, f in zip(pads, faces, strict=True)])


def _gap(
    rig: _Rig,
    pads: tuple[list[int], list[int]],
    faces: tuple[np.ndarray, np.ndarray],
    y_B: np.ndarray,
) -> float:
    pos = _faces_B(rig, pads[0], faces[0]) @ y_B
    neg = _faces_B(rig, pads[1], faces[1]) @ y_B
    return float(pos.min() - neg.max())


def _midway(rig: _Rig, side_pads: tuple[list[int], list[int]], y_B: np.ndarray) -> np.ndarray:
    """Point in B midway between the two sides' pad face centres (now), noise snapped."""
    faces = (_pad_faces(rig, side_pads[0], -y_B), _pad_faces(rig, side_pads[1], y_B))
    centres = [_faces_B(rig, p, f).mean(axis=0) for p, f in zip(side_pads, faces, strict=True)]
    mid = 0.5 * (centres[0] + centres[1])
    return np.where(np.abs(mid) < _SNAP, 0.0, np.round(mid, 9))


def _reach_along(rig: _Rig, g: int, axis_B: np.ndarray) -> float:
    """Farthest point [m] of geom ``g`` along ``axis_B`` (from B's origin), by :func:`_support`."""
    c = rig.geom_centres_B()[g]
    return float(c @ axis_B) + _support(rig.model, g, rig.geom_rot_B(g).T @ axis_B)


def _grasp_depth(
    rig: _Rig,
    open_state: np.ndarray,
    tcp_B: np.ndarray,
    R_BG: np.ndarray,
    half: np.ndarray,
) -> np.ndarray:
    """The tool point moved along the approach, away from the palm, as far as a grasp needs.

    Midway between the pads is where the pads' centres hold the brick's; a grasp also needs
    the fingers' farthest point at least :data:`TIP_CLEARANCE` short of the brick's far face,
    which rests on a floor, when open, and :data:`GRIP_TIP_CLEARANCE` as they are now (closed
    on the probe or the brick, at the brick's width: a linkage's fingertips move along the
    approach as it closes); and the open gripper's palm (its geoms that do not move) clear of
    the brick: a palm reaching between short pads. Fingers that touch the brick open are not
    moved away from: that gripper does not open around it (:func:`_squeeze`). When either
    fails at the midpoint the tool point moves towards the fingertips until both hold (the
    palm by :data:`PALM_CLEARANCE`), and the pads hold the brick nearer the face by the palm.
    """
    z_B = R_BG[:, 2]
    entry = rig.state()
    placed = dict(rig.placed)
    shift = 0.0
    for state, clearance in ((open_state, TIP_CLEARANCE), (entry, GRIP_TIP_CLEARANCE)):
        rig.restore(state)
        reach = max(_reach_along(rig, int(g), z_B) for g in rig.geoms)
        shift = max(shift, reach + clearance - half[2] - float(tcp_B @ z_B))
    rig.restore(open_state)

    def touches(s: float, margin: float) -> bool:
        rig.place_box("brick", tcp_B + s * z_B, R_BG)
        g = rig.box_geoms["brick"]
        before = float(rig.model.geom_margin[g])
        rig.model.geom_margin[g] = margin
        mujoco.mj_forward(rig.model, rig.data)
        hit = False
        for c in rig.data.contact[: rig.data.ncon]:
            pair = (int(c.geom1), int(c.geom2))
            other = pair[1] if pair[0] == g else pair[0]
            palm = not rig.moving_body[rig.model.geom_bodyid[other]]
            hit = hit or (g in pair and palm and c.dist < margin)
        rig.model.geom_margin[g] = before
        rig.place_box(None)
        return hit

    if touches(shift, 0.0):
        lo, hi = shift, shift + 2.0 * half[2] + rig.scale
        if touches(hi, PALM_CLEARANCE):
            rig.restore(entry)
            rig.placed = placed
            return tcp_B  # nothing clears it: _squeeze says what touches
        for _ in range(DEPTH_STEPS):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if touches(mid, PALM_CLEARANCE) else (lo, mid)
        shift = hi
    out = tcp_B + shift * z_B
    rig.restore(entry)
    rig.placed = placed
    return np.where(np.abs(out) < _SNAP, 0.0, np.round(out, 9))


def _squeeze(
    rig: _Rig, open_state: np.ndarray, u_closed: np.ndarray, pos_B: np.ndarray, R_BG: np.ndarray
) -> None:
    """From open, close on a brick-sized box centred at ``pos_B`` (tool axes)."""
    rig.restore(open_state)
    rig.place_box("brick", pos_B, R_BG)
    if rig.box_contacts("brick"):
        touched = ", ".join(sorted(rig.name(g) for g in rig.box_contacts("brick")))
        if all(rig.moving_body[rig.model.geom_bodyid[g]] for g in rig.box_contacts("brick")):
            width = 2000.0 * float(rig.model.geom_size[rig.box_geoms["brick"], 1])
            raise _Problem(
                "mjcf",
                f"the gripper cannot open wider than the brick: open, its fingers touch a "
                f"brick centred on its tool point ({touched}), the brick is {width:.1f} mm "
                f"wide; valid: a gripper that opens wider than the brick",
            )
        raise _Problem(
            "mjcf",
            f"the open gripper already touches a brick centred on its tool point ({touched}); "
            f"valid: a gripper that opens around the brick",
        )
    rig.settle(u_closed, "squeezing a brick-sized box")


class _Actions:
    """Gripper actions as a plan commands them: the gap ramped linearly, through the gap map."""

    def __init__(
        self,
        rig: _Rig,
        pads: tuple[list[int], list[int]],
        faces: tuple[np.ndarray, np.ndarray],
        y_B: np.ndarray,
        fractions: np.ndarray,
        gaps: np.ndarray,
        u_open: np.ndarray,
        u_closed: np.ndarray,
    ) -> None:
        self.rig, self.pads, self.faces, self.y_B = rig, pads, faces, y_B
        self.fractions, self.gaps = fractions, gaps
        self.u_open, self.u_closed = u_open, u_closed
        self.open_width = min(float(gaps[-1]), GRASP_OPEN_WIDTH)
        self.squeeze_width = float(gaps[0])
        self.last: tuple[float, list[float], float] = (math.nan, [], math.nan)

    def ctrl(self, width: float) -> np.ndarray:
        """Command for gap ``width`` [m] (as :meth:`GripperCalibration.ctrl_for_width`)."""
        s = float(np.clip(np.interp(width, self.gaps, self.fractions), 0.0, 1.0))
        if width <= self.squeeze_width:
            s = 0.0
        return self.u_closed + s * (self.u_open - self.u_closed)

    def gap(self) -> float:
        return _gap(self.rig, self.pads, self.faces, self.y_B)

    def ramp(self, state: np.ndarray, duration: float, closing: bool) -> Iterator[float]:
        """From ``state``, ramp the commanded gap over ``duration`` [s]; yield each step's
        time [s] (the rig's state is that step's)."""
        rig = self.rig
        rig.restore(state)
        dt = rig.model.opt.timestep
        for k in range(1, max(1, round(duration / dt)) + 1):
            u = min(1.0, k * dt / duration)
            rig.step(self.ctrl(self.open_width * ((1.0 - u) if closing else u)))
            yield k * dt

    def grip_steady_at(self, open_state: np.ndarray, duration: float, squeeze: np.ndarray) -> float:
        """Time [s] from which the grip stays steady while closing over ``duration``, or inf."""
        rig = self.rig
        steady_since, last = math.inf, math.nan
        for t in self.ramp(open_state, duration, closing=True):
            gap = self.gap()
            forces = rig.box_contacts("brick")
            per_side = [sum(forces.get(g, 0.0) for g in side) for side in self.pads]
            still = (
                math.isfinite(last) and abs(gap - last) < STEADY_GAP_SPEED * rig.model.opt.timestep
            )
            ok = still and all(
                f >= GRIP_FORCE_SHARE * s for f, s in zip(per_side, squeeze, strict=True)
            )
            if not ok:
                steady_since = math.inf
            elif not math.isfinite(steady_since):
                steady_since = t
            speed = abs(gap - last) / rig.model.opt.timestep if math.isfinite(last) else math.nan
            last = gap
        self.last = (duration, per_side, speed)
        return steady_since

    def released_at(self, squeezed: np.ndarray, duration: float, clear_gap: float) -> float:
        """Time [s] at which the pad gap first reaches ``clear_gap`` while opening, or inf."""
        for t in self.ramp(squeezed, duration, closing=False):
            if self.gap() >= clear_gap:
                return t
        return math.inf

    @staticmethod
    def shortest(done_at: Callable[[float], float], what: str, measured: str = "") -> float:
        """The shortest ramp T (a multiple of :data:`ACTION_RESOLUTION`) with
        ``done_at(T) <= T - ACTION_HOLD``: doubling, then bisection. ``measured`` says what
        the longest ramp achieved, in the error."""

        def ok(k: int) -> bool:
            T = k * ACTION_RESOLUTION
            return done_at(T) <= T - ACTION_HOLD + 1e-12

        k_max = round(MAX_ACTION_TIME / ACTION_RESOLUTION)
        hi = 1
        while not ok(hi):
            if hi >= k_max:
                raise _Problem(
                    "mjcf",
                    f"the gripper does not {what} within {MAX_ACTION_TIME:g} s of a ramped "
                    f"command{measured}; valid: a gripper that closes and opens within that, "
                    f"or set [gripper] closed_command (a command that squeezes sooner) or "
                    f"open_command",
                )
            hi = min(2 * hi, k_max)
        lo = hi // 2  # not ok (or 0)
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if ok(mid):
                hi = mid
            else:
                lo = mid
        return round(hi * ACTION_RESOLUTION, 9)


def _close_time(
    actions: _Actions, open_on_brick: np.ndarray, squeeze: np.ndarray, width: float
) -> tuple[float, float]:
    """The close time [s] and the squeeze width [m] (:attr:`GripperCalibration.squeeze_width`).

    A plan ramps the commanded gap to 0 through the gap map, so the closed command arrives
    only as the ramp ends, or never: where the free fingers pass each other (a negative
    closed width) a gap of 0 is a command short of closed, and a gripper without a force range
    that saturates (its squeeze the gain times the command's travel past the brick: robosuite's
    Robotiq 140) squeezes with a fraction of its squeeze; a squeeze that builds through a
    compliant linkage after the command arrives (the xArm gripper's soft loop constraints, 0.3
    s from a step) is not steady by the ramp's end. Such a gripper is given the closed command
    as soon as the commanded gap reaches the brick's width ``width``, and measured again.
    """
    what = "close on a brick-sized box"
    try:
        return actions.shortest(
            lambda T: actions.grip_steady_at(open_on_brick, T, squeeze), what
        ), actions.squeeze_width
    except _Problem:
        first = actions.last
    actions.squeeze_width = width

    def said(last: tuple[float, list[float], float]) -> str:
        T, per_side, speed = last
        return (
            f"{', '.join(f'{f:.3g}' for f in per_side)} N at the end of a {T:g} s ramp, "
            f"the gap changing by {1000 * speed:.2g} mm/s"
        )

    try:
        return actions.shortest(
            lambda T: actions.grip_steady_at(open_on_brick, T, squeeze), what
        ), width
    except _Problem:
        measured = (
            f": held closed, the pads squeeze the box with "
            f"{', '.join(f'{f:.3g}' for f in squeeze)} N a side (needed: "
            f"{100 * GRIP_FORCE_SHARE:g} % of that, the gap still to "
            f"{1000 * STEADY_GAP_SPEED:g} mm/s, {1000 * ACTION_HOLD:g} ms before the ramp "
            f"ends); the ramp reached {said(first)}, and closed once the commanded gap "
            f"reaches the brick's width {said(actions.last)}"
        )
    return actions.shortest(
        lambda T: actions.grip_steady_at(open_on_brick, T, squeeze), what, measured
    ), width


def calibrate_gripper(
    gripper: PreparedGripper,
    brick_half_extents: np.ndarray,
    brick_friction: np.ndarray,
    options: CalibrationOptions,
    *,
    src: str,
    pads: tuple[tuple[str, ...], tuple[str, ...]] | None = None,
    tcp: TcpOverride | None = None,
    open_command: np.ndarray | None = None,
    closed_command: np.ndarray | None = None,
) -> GripperCalibration:
    """Measure a prepared gripper (see the module docstring for the method).

    Args:
        gripper: The prepared gripper.
        brick_half_extents: Half sizes of the brick [m]: length (tool x), width (closing
            axis y), height (approach z).
        brick_friction: Friction of the brick geom (sliding, torsional, rolling).
        options: The scene's timestep and solver options.
        src: The description file, named in messages.
        pads: Pad geom names per finger instead of finding them.
        tcp: Tool point instead of calibrating it.
        open_command: Open command (prepared actuators) instead of finding it.
        closed_command: Closed command likewise.

    Raises:
        RobotError: The fingers do not move or settle, no pads are found, the pads do not
            squeeze the box, the gap does not grow with the command, or the gripper cannot
            open wider than the brick; one line naming ``src`` and the ``[gripper]`` field.
    """
    try:
        return _calibrate(
            gripper,
            np.asarray(brick_half_extents, dtype=float),
            np.asarray(brick_friction, dtype=float),
            options,
            pads,
            tcp,
            open_command,
            closed_command,
        )
    except _Problem as problem:
        raise RobotError(f"{src}: [gripper] {problem.field}: {problem.message}") from None


def _tool_site(rig: _Rig, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Position and rotation in B of an overridden tool site fixed to the gripper's root."""
    m = rig.model
    sid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, GRIPPER_PREFIX + name)
    root_weld = m.body_weldid[rig.root]
    if sid < 0 or m.body_weldid[m.site_bodyid[sid]] != root_weld:
        sites = [
            (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SITE, s) or "").removeprefix(GRIPPER_PREFIX)
            for s in range(m.nsite)
            if m.body_weldid[m.site_bodyid[s]] == root_weld
        ]
        valid = ", ".join(s for s in sites if s) or "(none)"
        raise _Problem("tcp", f"'{name}' is not a site fixed to the gripper's root; valid: {valid}")
    p, R = rig.root_pose()
    return R.T @ (rig.data.site_xpos[sid] - p), R.T @ rig.data.site_xmat[sid].reshape(3, 3)


def _calibrate(
    gripper: PreparedGripper,
    half: np.ndarray,
    friction: np.ndarray,
    options: CalibrationOptions,
    pads: tuple[tuple[str, ...], tuple[str, ...]] | None,
    tcp: TcpOverride | None,
    open_command: np.ndarray | None,
    closed_command: np.ndarray | None,
) -> GripperCalibration:
    rig = _Rig(gripper, options, half, friction)
    m = rig.model
    if open_command is None or closed_command is None:
        found_open, found_closed = _commands(rig, gripper)
    u_open = found_open if open_command is None else np.asarray(open_command, dtype=float)
    u_closed = found_closed if closed_command is None else np.asarray(closed_command, dtype=float)

    rig.settle(u_closed, "closing")
    c_closed = rig.geom_centres_B()
    rig.settle(u_open, "opening")
    c_open = rig.geom_centres_B()
    open_state = rig.state()
    axes = _axes(rig, c_open, c_closed, tcp)
    rig.set_stroke(2.0 * max(axes.travel.values()), axes.side)

    tcp_B = None
    if tcp is not None and tcp.site is not None:
        tcp_B, R_site = _tool_site(rig, tcp.site)
        axes = _Axes(R_site, axes.side, axes.travel)
    elif tcp is not None:
        tcp_B = np.array(tcp.pos)
    R_BG = axes.R_BG
    y_B = R_BG[:, 1]

    # Pads: first what a brick-wide probe between the fingertips touches; then what a brick
    # centred midway between those pads touches, until that stays the same.
    named = None if pads is None else _named_pads(rig, axes, pads)
    among = None if named is None else set(named[0] + named[1])
    fixed_tcp = tcp_B is not None
    if tcp_B is None:
        positions = _probe_positions(rig, axes, half)
        side_pads, _ = _find_pads(rig, axes, open_state, u_closed, positions, named)
        tcp_B = _midway(rig, side_pads, y_B)
        tcp_B = _grasp_depth(rig, open_state, tcp_B, R_BG, half)
    else:
        side_pads = ([], [])
    for _ in range(PAD_ITERATIONS):
        _squeeze(rig, open_state, u_closed, tcp_B, R_BG)
        found = _touching(rig, axes, "brick", among, share=PAD_FORCE_SHARE)
        if not found[0] or not found[1]:
            touched = ", ".join(sorted(rig.name(g) for g in rig.box_contacts("brick")))
            raise _Problem(
                "pads",
                f"no pads found: a brick centred on the tool point is touched by "
                f"{touched or 'nothing'} when the gripper closes; valid: fingers that squeeze "
                f"it from both sides, or set pads = [[...], [...]]",
            )
        if named is not None:
            side_pads = named  # they press on the brick from both sides: keep them all
            break
        if found == side_pads:
            break
        side_pads = found
        if not fixed_tcp:
            tcp_B = _midway(rig, side_pads, y_B)
            tcp_B = _grasp_depth(rig, open_state, tcp_B, R_BG, half)
    pos_pads, neg_pads = side_pads

    # Squeeze with stiff pads: normal forces per side, the gap, and the tool point again.
    stiff_pad_model(m, pos_pads + neg_pads)
    _squeeze(rig, open_state, u_closed, tcp_B, R_BG)
    forces = rig.box_contacts("brick")
    per_side = np.array([sum(forces.get(g, 0.0) for g in side) for side in side_pads])
    if np.min(per_side) <= 0.0:
        raise _Problem(
            "pads",
            f"the pads do not press on a brick centred on the tool point when closed (forces "
            f"{per_side.round(3).tolist()} N); valid: pads that face each other",
        )
    others = tuple(
        sorted(rig.name(g) for g, f in forces.items() if g not in pos_pads + neg_pads and f > 0)
    )
    faces = (_pad_faces(rig, pos_pads, -y_B), _pad_faces(rig, neg_pads, y_B))
    gap_on_brick = _gap(rig, side_pads, faces, y_B)
    if not fixed_tcp:
        tcp_B = _midway(rig, side_pads, y_B)
        tcp_B = _grasp_depth(rig, open_state, tcp_B, R_BG, half)

    # Gap map: closed to open, fingers free.
    rig.place_box(None)
    fractions = np.linspace(0.0, 1.0, SWEEP_POINTS)
    gaps, qpos = [], []
    for s in fractions:
        rig.settle(u_closed + s * (u_open - u_closed), f"sweeping the command (s = {s:.2f})")
        gaps.append(_gap(rig, side_pads, faces, y_B))
        qpos.append(rig.data.qpos[m.jnt_qposadr[rig.joints]].copy())
    gap_arr = np.array(gaps)
    if np.any(np.diff(gap_arr) < -1e-5):
        shown = ", ".join(f"{1000 * g:.1f}" for g in gap_arr)
        raise _Problem(
            "mjcf",
            f"the pad gap does not grow with the command from closed to open ({shown} mm); "
            f"valid: fingers that open monotonically (or set open_command and closed_command)",
        )
    gap_arr = np.maximum.accumulate(gap_arr)
    width = 2.0 * float(half[1])
    if gap_arr[-1] <= width:
        raise _Problem(
            "mjcf",
            f"the gripper cannot open wider than the brick: its pads open to "
            f"{1000 * gap_arr[-1]:.1f} mm, the brick is {1000 * width:.1f} mm wide; valid: a "
            f"gripper that opens wider than the brick",
        )

    narrowest = 2.0 * float(min(half[0], half[1]))
    if pad_clearance(narrowest, float(gap_arr[-1])) is None:
        raise _Problem(
            "mjcf",
            f"the gripper opens to {1000 * gap_arr[-1]:.1f} mm, and a grasp needs the brick's "
            f"{1000 * narrowest:.1f} mm plus {1000 * MIN_PAD_CLEARANCE:g} mm beside each face; "
            f"valid: a gripper that opens to at least "
            f"{1000 * (narrowest + 2 * MIN_PAD_CLEARANCE):.1f} mm",
        )

    # Action times: the plan's ramps of the commanded gap, closing on the box and opening.
    actions = _Actions(rig, side_pads, faces, y_B, fractions, gap_arr, u_open, u_closed)
    rig.restore(open_state)
    rig.settle(actions.ctrl(actions.open_width), "opening to the grasp's width")
    rig.place_box("brick", tcp_B, R_BG)
    open_on_brick = rig.state()  # (the state holds the box's mocap pose)
    _squeeze(rig, open_state, u_closed, tcp_B, R_BG)
    squeezed = rig.state()
    close_time, squeeze_width = _close_time(actions, open_on_brick, per_side, width)
    clear = min(RELEASE_CLEARANCE, 0.25 * (actions.open_width - width))
    open_time = actions.shortest(
        lambda T: actions.released_at(squeezed, T, width + 2.0 * clear),
        "let go of a brick-sized box",
    )

    # Footprint at the open command, in the tool frame.
    rig.restore(open_state)
    footprint = []
    for g in map(int, rig.geoms):
        c, h = _aabb_G(rig, g, R_BG, tcp_B)
        footprint.append([c - h, c + h])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, R_BG.reshape(9))
    joint_names = tuple(
        (mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or "").removeprefix(GRIPPER_PREFIX)
        for j in rig.joints
    )
    return GripperCalibration(
        root_body=gripper.root_body,
        actuators=gripper.actuators,
        joints=joint_names,
        open_command=u_open,
        closed_command=u_closed,
        sweep_fraction=fractions,
        sweep_gap=gap_arr,
        sweep_qpos=np.array(qpos),
        open_width=float(gap_arr[-1]),
        closed_width=float(gap_arr[0]),
        squeeze_width=squeeze_width,
        pads=(tuple(rig.name(g) for g in pos_pads), tuple(rig.name(g) for g in neg_pads)),
        pad_faces=faces,
        pos_BG=tcp_B,
        quat_BG=quat,
        squeeze_force=float(per_side.mean()),
        squeeze_per_side=per_side,
        gap_on_brick=gap_on_brick,
        other_contacts=others,
        footprint_geoms=tuple(rig.name(int(g)) for g in rig.geoms),
        footprint_G=np.array(footprint),
        brick_half_extents=half.copy(),
        close_time=close_time,
        open_time=open_time,
        sim_time=rig.sim_time,
    )


PAD_CLEARANCE = 0.006
"""Gap between each open pad and the object's face it closes on [m]: twice the 3 mm by which
the tool arrives off the planned pick at full speed (:class:`~pickplace.planning.plan.PlanConfig`'s
``settle_time``), so a pad never lands on the object's top. The gripper opens to the object's
width plus this on each side, no wider: the less the fingers open, the nearer a wall the object
can lie. The planner's grasp candidates (:mod:`pickplace.planning.candidates`) use it where
the gripper opens that wide, and :data:`MIN_PAD_CLEARANCE` where it does not."""

MIN_PAD_CLEARANCE = 0.002
"""The least gap a side [m] for a grasp across a side the gripper opens to less than
``2 PAD_CLEARANCE`` wider than (an 80 mm opening across a 75 mm side): the pads come down
beside the faces along the approach, so what matters is the tool's error across the closing
axis, not along it: 0.3 mm at most at the pick, up to 3 mm higher up on the way down, where
the pads' lower edges pass the object's top (measured on the Panda hands, with these grasps
in 21 runs: the pads pressed on nothing before closing, the brick moved 0.2 mm at most, and
every one succeeded; docs/planning.md). Such grasps rank after every grasp with the whole
clearance that passes the same tests. A gripper that opens less than the narrowest side plus
this on each side has no candidate, and is refused here."""


def pad_clearance(width: float, max_open_width: float) -> float | None:
    """The gap a side [m] between the open pads and a side ``width`` [m] wide, for a gripper
    that opens to ``max_open_width`` [m]: :data:`PAD_CLEARANCE` where it opens that wide, else
    all that it opens beyond the side, down to :data:`MIN_PAD_CLEARANCE`; None below that."""
    spare = 0.5 * (max_open_width - width)
    if spare >= PAD_CLEARANCE:
        return PAD_CLEARANCE
    return spare if spare >= MIN_PAD_CLEARANCE else None


GRASP_OPEN_WIDTH = 0.10
"""Gap a gripper opens to around the brick for a grasp, at most [m]: 25 mm beside each face of
the 50 mm brick (less when the gripper opens less)."""
