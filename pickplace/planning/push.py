"""Pushing the object away from a wall, where no grasp of it fits.

Beside a wall, or in a corner, a gripper whose palm is long along its closing axis finds no
grasp whose open hand clears the walls (the footprint refusals of the ranking,
:mod:`pickplace.planning.candidates`), though one a few centimetres further in would. A person
slides the object out first; so does the planner, when no grasp candidate is feasible
(:meth:`~pickplace.planning.planner.PickPlacePlanner.plan`):

1. **Directions** (:func:`push_directions`): a box is pushed along the normals of its four
   side faces (a flat pusher on a face slides the box without turning it); any other object
   that does not roll (not one sphere) along the bin's axes and diagonals; a sphere is not
   pushed.
2. **The hand** (:class:`Pusher`): fingers closed, behind the object's side that faces the
   wall, turned from straight down as :meth:`Pusher.hand_rotation` turns it: its x-axis along
   the push or turned from it about the vertical by one of :data:`HAND_YAWS`, each with its
   twin a half turn further (the wrist the other way round), rolled by one of
   :data:`HAND_ROLLS` about the push (one end of a long palm up over a wall beside the
   object) and tilted by one of :data:`HAND_TILTS` about the horizontal across the push (the
   palm leaning forward over the object, away from the wall behind it). The tool lies on the
   object's line of push, the hand's lowest point :data:`PUSH_FLOOR_GAP` above the bin's floor
   (a flat pusher on a box that starts to tip keeps only its lowest contact, which cannot tip
   it unless the friction coefficient exceeds the box's half length over that height), the
   pre-flight's clearance from the object; its closed hull must clear the bin's walls and
   floor by that clearance at the push's start and at its end.
3. **How far** (:data:`PUSH_DISTANCES`, shortest first): the object's predicted pose (the
   start pose moved along the push) must lie inside the bin, the pre-flight's clearance from
   its walls, and some grasp candidate must be feasible there (the planner's own ranking and
   pre-flight; at most :data:`MAX_PREDICTED_PLANS` predicted poses are planned in full).
   The push then goes :data:`PUSH_OVERSHOOT` further where the bin has the room, so that a
   pose a few millimetres off the prediction is still pickable.
4. **The plan** (:meth:`Pusher.plan`): from the start, over the push's start at the transfer
   height, down behind the object, the push at :data:`PUSH_SPEED`, a back-off of
   :data:`PUSH_BACK_OFF` against the push (the fingers leave the side before rising), up to
   the transfer height, and a hold there (:data:`PUSH_HOLD`) while the object comes to rest.
   It carries nothing (no phases), is timed by the planner's Cartesian limits and
   pre-flighted against the world like every plan (the object is not part of the world: the
   fingers meet it on purpose); the planner pre-flights the pushes in order until one passes.

What the object does is the physics' to show: after the push the run plans the pick from the
object's pose as the simulation has it (:mod:`pickplace.sim.recovery`), and a run whose object
lies where no grasp fits even then (after at most one more push) ends ``no-feasible-plan``,
saying so.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from mink.lie import SE3, SO3

from pickplace.geometry import wrap_angle
from pickplace.planning.candidates import HandFootprint, HandObjectGaps
from pickplace.planning.grasp import yaw_of
from pickplace.planning.plan import (
    Plan,
    PlanConfig,
    Waypoint,
    time_keyframes,
)
from pickplace.planning.trajectory import Keyframe, PoseTrajectory
from pickplace.world.placements import footprint_inside
from pickplace.world.scene import BinGeometry, Scene

PUSH_DISTANCES = (0.03, 0.045, 0.06, 0.075, 0.09, 0.105, 0.12)
"""How far the object may be pushed [m], shortest first."""

PUSH_OVERSHOOT = 0.015
"""How much further than the shortest feasible distance the push goes [m] (capped by the
bin's room)."""

PUSH_SPEED = 0.05
"""Tool speed of the push itself [m/s], at most: slow, so that the object slides with the
fingers rather than being struck."""

PUSH_FLOOR_GAP = 0.010
"""Height of the closed hand's lowest point above the bin's floor during the push [m]: the
pre-flight's 5 mm clearance and 5 mm for the arm's tracking error across the push."""

PUSH_BACK_OFF = 0.010
"""How far the tool backs off against the push before rising [m]."""

PUSH_HOLD = 3.0
"""How long the plan holds the tool at the transfer height after the push [s]: the time the
object has to come to rest before the run plans its pick."""

STARTS_KEPT = 6
"""Most hand poses kept per push direction (the first that clear the bin at the start, with
their wrist-turned twins; the push takes those that clear it at its end too, in turn)."""

_SCREEN_SLACK = 0.010
"""How much nearer to the bin than the clearance a screened hand pose may be and still be
placed exactly [m]: the screen's distance from the object is its hull's reach, not the exact
distance, and a palm leaning over the object moves the exact pose back by up to this."""

_ITERATIONS = 30  # of the hand's placement and of its advancement to the touch
_TOUCH = 2e-4  # the hand touches the object nearer than this [m]

MAX_PREDICTED_PLANS = 4
"""Most predicted poses planned in full (the grasp candidates' pre-flights) per push search."""

DIAGONAL_DIRECTIONS = 8
"""Push directions of an object that is not a box: the bin's axes and diagonals."""

HAND_TILTS = tuple(math.radians(a) for a in (0, 20, 35))
"""Tilts of the closed hand's approach from straight down about the horizontal across the push
[rad], the fingertips back and the palm forward over the object, in the order tried: a palm
that meets the wall behind the object clears it leaning forward. The fingers' front then
leans over the object's top edge and may push there: Menagerie's Panda hand tilted 20° pushed
a brick at its top edge, which rose 9 mm onto the fingers and fell back when they left (the
run then ends ``no-feasible-plan`` where the brick lies). Tilts gain more than such falls
cost: over 300 uniform poses (Menagerie's Panda hand, seeds 91300-91599) 39 pushes and 33
picks after them; with the hand's leading part held below half the height at which a push
tips the brick, none (that hand's fingers lead with their upper part at most turns); with the
leading part centred on the line of push, 22 and 16."""

HAND_ROLLS = tuple(math.radians(a) for a in (0, 25, -25, 45, -45))
"""Rolls of the closed hand about the push's direction [rad], in the order tried: in a
corner, where a long palm meets a wall at either end, rolling it raises one end over the wall
beside the object."""

HAND_YAWS = tuple(math.radians(a) for a in (0, 90, 45, -45, 30, -30, 60, -60, 15, -15, 75, -75))
"""Turns of the closed hand about the vertical from its x-axis along the push [rad], in the
order tried: a palm long along the closing axis that meets a wall across the push may fit
along it, or diagonally in a corner (the closed fingers push with whichever side leads)."""


@dataclass(frozen=True)
class Push:
    """One push of the object across the bin's floor.

    Attributes:
        label: In words, e.g. ``"push the object 45 mm away from bin1's -x wall"``.
        d_W: The push's direction, horizontal unit vector in world.
        distance: How far the tool pushes once it touches [m].
        touch: How far the tool moves along the push from its start before the hand touches
            the object [m].
        X_WG_start: The tool where the push starts (behind the object, fingers closed).
        X_WO_after: Where the object is predicted to lie after it (moved along ``d_W``).
        wall: The wall the object is pushed away from (the one its back faces), e.g.
            ``"-y wall"``.
    """

    label: str
    d_W: np.ndarray
    distance: float
    touch: float
    X_WG_start: SE3
    X_WO_after: SE3
    wall: str


class PushTrajectory(PoseTrajectory):
    """A push's tool trajectory: its keyframes timed, and the push it carries out.

    Args:
        keyframes: The timed keyframes (:meth:`Pusher.plan`'s, by name: ``push-start`` where
            the tool is behind the object, ``push-retreat`` where it is back up, then the
            hold).
        profile: Motion profile name.
        push: The push.
    """

    def __init__(self, keyframes: list[Keyframe], profile: str, push: Push):
        super().__init__(keyframes, profile)
        self.push = push
        times = {k.name: k.t for k in keyframes}
        self.push_start_time = times["push-start"]
        """When the tool reaches the push's start, behind the object [s]."""
        self.push_end_time = times["push-retreat"]
        """When the tool is back up after the push [s]: from then on the run waits for the
        object to rest and plans its pick."""


def push_directions(scene: Scene, X_WO: SE3, bin_: BinGeometry) -> list[tuple[np.ndarray, str]]:
    """Horizontal push directions in world, with the wall of ``bin_`` each pushes away from:
    a box's face normals (into the box from each side face), any other object's
    :data:`DIAGONAL_DIRECTIONS` bin directions; none for a round object."""
    shape = scene.object
    if shape.is_round:
        return []
    R_WB = bin_.X_WB.rotation().as_matrix()
    if shape.box_half_extents is not None:
        R_WO = X_WO.rotation().as_matrix()
        dirs = [s * R_WO[:, a] for a in (0, 1) for s in (1.0, -1.0)]
    else:
        angles = np.arange(DIAGONAL_DIRECTIONS) * (2.0 * math.pi / DIAGONAL_DIRECTIONS)
        dirs = [R_WB @ np.array([math.cos(a), math.sin(a), 0.0]) for a in angles]
    out = []
    for d in dirs:
        d = np.array([d[0], d[1], 0.0])
        norm = float(np.linalg.norm(d))
        if norm < 1e-9:
            continue
        d /= norm
        d_B = R_WB.T @ d
        a = int(np.argmax(np.abs(d_B[:2])))
        wall = f"{'-' if d_B[a] > 0 else '+'}{'xy'[a]} wall"  # behind the object
        out.append((d, wall))
    return out


def _about(axis: npt.ArrayLike, angle: float) -> np.ndarray:
    """The rotation matrix by ``angle`` [rad] about ``axis`` (made unit; zero: identity)."""
    u = np.asarray(axis, dtype=np.float64)
    norm = float(np.linalg.norm(u))
    if norm < 1e-12 or angle == 0.0:
        return np.eye(3)
    return SO3.exp(u / norm * angle).as_matrix()


class Pusher:
    """Plans pushes for a planner (see the module docstring).

    Args:
        scene: The scene.
        hand: The hand's collision geoms (all of them) in the tool frame.
        gaps: The same geoms against the object.
        closed_width: The finger gap commanded closed [m] (the planner's).
        clearance: The pre-flight's clearance [m].
        clearance_z: The transfer height of the tool [m].
        home_yaw: The tool's yaw at home [rad] (of two hand poses a half turn apart, the one
            nearer it is tried first).
    """

    def __init__(
        self,
        scene: Scene,
        hand: HandFootprint,
        gaps: HandObjectGaps,
        closed_width: float,
        clearance: float,
        clearance_z: float,
        home_yaw: float,
    ) -> None:
        self.scene = scene
        self.hand = hand
        self.gaps = gaps
        self.clearance = float(clearance)
        self.clearance_z = float(clearance_z)
        self.home_yaw = float(home_yaw)
        self.width = float(closed_width)
        self.hull = hand.hull_G(self.width)  # the closed hand's hull vertices in G
        # The hulls' edges, as pairs of indices into ``hull`` (each geom's after the others').
        counts = np.bincount(hand.hull_geom, minlength=len(hand.geom_ids))
        offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self.edges = np.concatenate(
            [e + o for e, o in zip(hand.hull_edges, offsets, strict=True) if len(e)]
        )
        self._turns = [
            (yaw + half, tilt, roll)
            for roll in HAND_ROLLS
            for tilt in HAND_TILTS
            for yaw in HAND_YAWS
            for half in (0.0, math.pi)
        ]
        x = np.array([1.0, 0.0, 0.0])
        self._along_x = np.array([self.hand_rotation(x, *t) for t in self._turns])

    @staticmethod
    def hand_rotation(d_W: np.ndarray, yaw: float, tilt: float, roll: float) -> np.ndarray:
        """R_WG of the closed hand pushing along ``d_W``: approach down, G's x along the push
        turned by ``yaw`` [rad] about the vertical, then the approach tilted by ``tilt`` [rad]
        about the horizontal across the push (fingertips back) and rolled by ``roll`` [rad]
        about the push's direction."""
        z_G = np.array([0.0, 0.0, -1.0])
        c, sn = math.cos(yaw), math.sin(yaw)
        x_G = np.array([c * d_W[0] - sn * d_W[1], sn * d_W[0] + c * d_W[1], 0.0])
        y_G = np.cross(z_G, x_G)
        R_tilt = _about(d_W, roll) @ _about(np.cross([0.0, 0.0, 1.0], d_W), tilt)
        return np.asarray(R_tilt @ np.column_stack([x_G, y_G, z_G]))

    def placements(
        self, R_WG: np.ndarray, X_WO: SE3, d_W: np.ndarray, bin_: BinGeometry
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where the closed hand at each orientation ``R_WG`` (n, 3, 3) goes to push the
        object at ``X_WO`` along ``d_W``, to a first approximation: the tool's position [m]
        (n, 3), on the object's line of push, with the hand's lowest point
        :data:`PUSH_FLOOR_GAP` above the floor and the clearance between the object's back
        and the hand's reach towards it (the hull below the object's top, its vertices and its
        edges' crossings of the top's plane, within the object's width across the push); and
        the tool's distance behind the object's centre along the push [m] (n,), inf for a hand
        that would pass beside the object."""
        P = np.einsum("nij,vj->nvi", R_WG, self.hull)  # the hull's vertices from the tool, in W
        z = bin_.floor_top_z + PUSH_FLOOR_GAP - P[..., 2].min(axis=1)  # (n,)
        R_WO, p_WO = X_WO.rotation().as_matrix(), X_WO.translation()
        shape = self.scene.object
        top = float(p_WO[2] + shape.support(R_WO.T @ np.array([0.0, 0.0, 1.0])))
        back = shape.support(R_WO.T @ -d_W)
        across = np.array([-d_W[1], d_W[0], 0.0])
        wide = (shape.support(R_WO.T @ across), shape.support(R_WO.T @ -across))
        # The hull below the object's top: its vertices there and its edges' crossings of
        # the top's plane (a leaning finger's front edge meets the object where it crosses).
        h = top - z  # the top's height from the tool [m], (n,)
        A, B = P[:, self.edges[:, 0]], P[:, self.edges[:, 1]]
        za, zb = A[..., 2] - h[:, None], B[..., 2] - h[:, None]
        crossing = za * zb < 0.0
        t = np.where(crossing, za / np.where(crossing, za - zb, 1.0), 0.0)
        Q = np.concatenate([P, A + t[..., None] * (B - A)], axis=1)
        low = np.concatenate([P[..., 2] < h[:, None], crossing], axis=1)
        ahead, lateral = Q @ d_W, Q @ across
        meets = low & (lateral < wide[0]) & (lateral > -wide[1])
        reach = np.where(meets, ahead, -np.inf).max(axis=1)
        s = back + self.clearance + reach
        p = np.column_stack([np.full(len(z), p_WO[0]), np.full(len(z), p_WO[1]), z])
        p -= np.where(np.isfinite(s), s, 0.0)[:, None] * d_W
        return p, np.where(np.isfinite(s), s, np.inf)

    def start_pose(
        self,
        X_WO: SE3,
        d_W: np.ndarray,
        bin_: BinGeometry,
        yaw: float = 0.0,
        tilt: float = 0.0,
        roll: float = 0.0,
    ) -> tuple[SE3, float] | None:
        """The tool behind the object for a push along ``d_W``, the hand turned as
        :meth:`hand_rotation` turns it and placed as :meth:`placements` places it, then moved
        along the push until it is the clearance (to within 1 mm over) from the object; with
        how far the tool moves along the push before the hand touches the object [m]. None
        when the hand cannot be put there so, or passes beside the object."""
        R_WG = self.hand_rotation(d_W, yaw, tilt, roll)
        p_first, s_first = (a[0] for a in self.placements(R_WG[None], X_WO, d_W, bin_))
        if not math.isfinite(s_first):
            return None
        p_WO = X_WO.translation()
        R_WO = X_WO.rotation().as_matrix()
        R_OG = (R_WO.T @ R_WG)[None]
        widths = np.array([self.width])
        p_low = p_first + s_first * d_W  # on the line of push, level with the object's centre

        def gap(s: float) -> float:
            p_OG = (R_WO.T @ (p_low - s * d_W - p_WO))[None]
            return float(self.gaps.gaps(R_OG, p_OG, widths, 1.0)[0][0])

        # Back from the object until the hand is the clearance from it (the fingers behind
        # it, or a palm leaning over it), to within a millimetre over.
        s = s_first
        for _ in range(_ITERATIONS):
            g = gap(s)
            if self.clearance <= g <= self.clearance + 1e-3:
                break
            s += self.clearance - g + (0.5e-3 if g < self.clearance else 0.0)
        else:
            return None
        # How far the hand moves along the push before it touches: conservative advancement
        # (moved by its distance from the object it cannot pass into it).
        touch = 0.0
        for _ in range(_ITERATIONS):
            g = gap(s - touch)
            if g < _TOUCH:
                break
            touch += g
            if touch > s:  # passes beside it
                return None
        else:
            return None
        X_WG = SE3.from_rotation_and_translation(SO3.from_matrix(R_WG), p_low - s * d_W)
        return X_WG, touch

    def pushes(
        self,
        X_WO: SE3,
        bin_: BinGeometry,
        feasible_at: Callable[[SE3], bool],
        pickable_at: Callable[[SE3], bool],
    ) -> Iterator[Push]:
        """The pushes after which a grasp is feasible, shortest first (each then
        :data:`PUSH_OVERSHOOT` more where the bin has the room), each of its hand poses
        that clears the bin at the push's start and end in turn.

        Args:
            X_WO: The object's pose.
            bin_: The bin it lies in.
            feasible_at: Whether a grasp plan is feasible with the object at a pose (the
                planner's full pre-flight; called at most :data:`MAX_PREDICTED_PLANS` times).
            pickable_at: Whether some grasp passes the cheap tests at a pose (fast).

        Yields:
            The pushes, for the caller to pre-flight.
        """
        starts = [
            (d, wall, self._starts(X_WO, d, bin_))
            for d, wall in push_directions(self.scene, X_WO, bin_)
        ]
        planned = 0
        for distance in PUSH_DISTANCES:
            for d, wall, hands in starts:
                X_after = self._moved(X_WO, d, distance)
                fitting = [
                    (X, touch)
                    for X, touch in hands
                    if self._fits(X_after, X, d, touch + distance, bin_)
                ]
                if not fitting or not pickable_at(X_after):
                    continue
                if planned >= MAX_PREDICTED_PLANS:
                    return
                planned += 1
                if not feasible_at(X_after):
                    continue
                for X_WG, touch in fitting:
                    further = distance + PUSH_OVERSHOOT
                    room = self._fits(self._moved(X_WO, d, further), X_WG, d, touch + further, bin_)
                    pushed = further if room else distance
                    yield Push(
                        f"push the object {pushed * 1000:.0f} mm away from {bin_.name}'s {wall}",
                        d,
                        pushed,
                        touch,
                        X_WG,
                        self._moved(X_WO, d, pushed),
                        wall,
                    )

    def _starts(self, X_WO: SE3, d_W: np.ndarray, bin_: BinGeometry) -> list[tuple[SE3, float]]:
        """Up to :data:`STARTS_KEPT` push starts along ``d_W`` (rolls, tilts, then yaws, in
        order)
        whose closed hand clears the bin, each with its travel to the touch [m]; each with its
        twin turned half a turn about the approach (the fingers swapped, the wrist the other
        way round), the one whose yaw is nearer home's first.

        Every turn is screened at once first: the hand placed as :meth:`placements` places
        it, its footprint against the bin tested in one batch (:data:`_SCREEN_SLACK` allowed);
        the search for the exact distance from the object and the footprint there follow for
        those that pass, in order."""
        turns = self._turns
        # The turns about the vertical commute with it: those along +x, turned to d.
        c, sn = float(d_W[0]), float(d_W[1])
        R = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]]) @ self._along_x  # (n, 3, 3)
        p, s0 = self.placements(R, X_WO, d_W, bin_)
        ok = np.isfinite(s0)
        R_BW = bin_.X_WB.inverse().rotation().as_matrix()
        distance = self.hand.distances(R_BW @ R, bin_.to_bin_frame(p), self.width, bin_)[0]
        ok &= distance >= self.clearance - _SCREEN_SLACK
        out: list[tuple[SE3, float]] = []
        for pair in range(0, len(turns), 2):
            keep = [i for i in (pair, pair + 1) if ok[i]]
            keep.sort(key=lambda i: abs(wrap_angle(yaw_of(SO3.from_matrix(R[i])) - self.home_yaw)))
            for i in keep:
                start = self.start_pose(X_WO, d_W, bin_, *turns[i])
                if start is None or self._hand_problem(start[0], bin_):
                    continue
                out.append(start)
                if len(out) == STARTS_KEPT:
                    return out
        return out

    @staticmethod
    def _moved(X_WO: SE3, d_W: np.ndarray, distance: float) -> SE3:
        return SE3.from_rotation_and_translation(
            X_WO.rotation(), X_WO.translation() + distance * d_W
        )

    def _hand_problem(self, X_WG: SE3, bin_: BinGeometry) -> bool:
        return self.hand.problem(X_WG, self.width, bin_, self.clearance) is not None

    def _fits(
        self, X_after: SE3, X_WG: SE3, d_W: np.ndarray, travel: float, bin_: BinGeometry
    ) -> bool:
        """The object's predicted footprint inside the walls by the clearance, and the hand at
        the push's end (``travel`` [m] from its start) clear of the bin."""
        if not footprint_inside(self.scene, X_after, bin_, self.clearance):
            return False
        X_end = SE3.from_rotation_and_translation(
            X_WG.rotation(), X_WG.translation() + travel * d_W
        )
        return not self._hand_problem(X_end, bin_)

    def plan(self, push: Push, X_WG_from: SE3, width_from: float, config: PlanConfig) -> Plan:
        """The push's plan from the tool pose ``X_WG_from`` with the fingers at ``width_from``
        [m], timed by ``config``'s Cartesian limits (see the module docstring)."""
        X0 = push.X_WG_start
        p0 = X0.translation()
        R = X0.rotation()

        def at(p: np.ndarray) -> SE3:
            return SE3.from_rotation_and_translation(R, p)

        up = np.array([0.0, 0.0, 1.0])
        p_end = p0 + (push.touch + push.distance) * push.d_W
        p_back = p_end - PUSH_BACK_OFF * push.d_W
        high = max(self.clearance_z, float(p0[2]))
        w = self.width
        waypoints = [
            Waypoint("start", X_WG_from, width_from),
            Waypoint("pre-push", at(np.array([p0[0], p0[1], high])), w, config.close_time),
            Waypoint("push-start", X0, w),
            Waypoint("push-end", at(p_end), w, (push.touch + push.distance) / PUSH_SPEED),
            Waypoint("push-back-off", at(p_back), w),
            Waypoint("push-retreat", at(p_back + (high - p_back[2]) * up), w),
        ]
        keyframes = time_keyframes(waypoints, config)
        end = keyframes[-1]
        keyframes.append(Keyframe("push-hold", end.t + PUSH_HOLD, end.X_WG, w))
        traj = PushTrajectory(keyframes, config.profile, push)
        return Plan(traj)


__all__ = [
    "DIAGONAL_DIRECTIONS",
    "HAND_ROLLS",
    "HAND_TILTS",
    "HAND_YAWS",
    "MAX_PREDICTED_PLANS",
    "PUSH_BACK_OFF",
    "PUSH_DISTANCES",
    "PUSH_FLOOR_GAP",
    "PUSH_HOLD",
    "PUSH_OVERSHOOT",
    "PUSH_SPEED",
    "STARTS_KEPT",
    "Push",
    "PushTrajectory",
    "Pusher",
    "push_directions",
]
