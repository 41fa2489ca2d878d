"""Rerun recording of a run: scene geometry, plan, per-tick state, health plots and events.

:class:`Recorder` is a :class:`~pickplace.sim.loop.TickObserver`. It writes to a ``.rrd`` file,
a viewer it spawns, a viewer at a gRPC URL, or several of them at once. Tick data is never
logged row by row: it is read from the run's preallocated :class:`~pickplace.sim.ticklog.TickLog`
and
sent with ``send_columns`` every ``flush_every`` ticks (or sooner, once ``flush_interval_s`` of
wall time has passed, so that a live viewer of a paced run stays current) and at the end, each
batch handed to the viewers at once. The file's bytes are encoded in memory and written in
``on_finish`` (also after Ctrl-C, SIGTERM or SIGHUP) to a temporary file, which is renamed onto
its path once it reads back complete, so the path holds either a complete recording (footer,
summary, verdict) or what was there before. See :class:`Recorder` for the file and the
viewers, and :mod:`pickplace.record.viewer` for the bounds on waiting for a viewer.

Timelines: ``sim_time`` (duration, the simulated time at the end of the tick) and ``tick``
(sequence, the control tick index k). Quaternions are stored xyzw. Lengths in m, angles in
rad, times in s unless stated.

=================================================  ==========================================
Entity path                                        Contents
=================================================  ==========================================
``world``                                          static: ``ViewCoordinates`` right-hand, z up
``world/static/<geom>``                            static: geoms of the world body (floor)
``world/bodies/<body>``                            body pose in world (``Transform3D``): one row
                                                   per tick for bodies that move (a joint in
                                                   their chain), static for the others (bins)
``world/bodies/<body>/<geom>``                     static: visual geom (box, sphere, capsule,
                                                   cylinder, ellipsoid, plane, mesh) at its
                                                   local pose in the body
``world/plan/path``                                static: planned tool path (``LineStrips3D``)
``world/plan/keyframes/<name>``                    static: keyframe pose with 5 cm axes and a
                                                   labelled point (keyframes at one position
                                                   show one label, "pick / settle / ...")
``world/plan/target_bin``                          static: target bin's free inner volume
                                                   (green box outline)
``world/plan/replans/<n>/path``                    from the moment the n-th plan replaced the
                                                   one executed (a ``replan`` event): its tool
                                                   path, orange for the stop after a failed
                                                   attempt, green for the next attempt's plan
``world/tool/planned``                             per tick: planned tool pose, 12 cm axes
``world/tool/commanded``                           per tick: FK of the commanded q, 9 cm axes
``world/tool/actual``                              per tick: simulated tool pose, 6 cm axes
``world/tool/manipulability_ellipsoid``            per tick: translational velocity ellipsoid
                                                   at the actual tool (half sizes 0.1·σt [m])
``plots/...``                                      per tick: one ``Scalars`` entity per entry of
                                                   :data:`~pickplace.record.blueprint.PLOTS`, which
                                                   declares each plot once
                                                   (path, view, series, style, what it reads
                                                   from the tick log) with its constant limit
                                                   lines (a row at the first and the last tick)
``events``                                         ``TextLog`` of the run's events and verdict
``summary``                                        static: JSON summary (``TextDocument``)
=================================================  ==========================================

Names containing ``/`` (``gripper/left_pad``) are escaped as one path part (``gripper\\/left_pad``);
unnamed bodies and geoms are called ``body<i>`` and ``geom<i>``. The file embeds a blueprint:
the 3D scene on the left; on the right the plot tabs of :data:`~pickplace.record.blueprint.PLOTS`
(health, tracking,
joints, gripper and IK) and the event log.
"""

from __future__ import annotations

import contextlib
import json
import time
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

import mujoco
import numpy as np
import rerun as rr

from pickplace.control.controllers import IK_STATUSES
from pickplace.errors import InvalidInputError, OutputError, RecordingError
from pickplace.outfile import OutputFile
from pickplace.record.archetypes import (
    SOLID,
    element_names,
    geom_archetype,
    geom_rgba,
    path_part,
    quat,
    scalar_columns,
    to_duration,
    transform_columns,
    xyzw,
)
from pickplace.record.blueprint import (
    LIMIT_LINES,
    PLOTS,
    RunVerdict,
    build_blueprint,
    label_groups,
    y_range_of,
)
from pickplace.record.rrd_file import read_back_problem
from pickplace.record.viewer import FINISH_TIMEOUT_S, ViewerRelay, parse_viewer_url, spawn_viewer
from pickplace.signals import deferred_interrupts
from pickplace.sim.events import EventKind

if TYPE_CHECKING:
    from pickplace.sim.events import Event
    from pickplace.sim.loop import Simulation
    from pickplace.sim.ticklog import TickLog
    from pickplace.sim.verdict import RunResult

APPLICATION_ID = "pickplace"
SPAWN_PORT = 9876
ELLIPSOID_SCALE = 0.1  # half sizes of the manipulability ellipsoid = this · σt [m per m/rad]
ENCODE_TIMEOUT_S = 30.0  # bound on encoding what was logged (normally milliseconds) [s]
VIEWER_FINISH_AFTER_INTERRUPT_S = 1.0  # time a viewer gets for the rest after Ctrl-C [s]

TOOL_AXES = {"planned": 0.12, "commanded": 0.09, "actual": 0.06}
LEVELS = {
    "info": rr.TextLogLevel.INFO,
    "warn": rr.TextLogLevel.WARN,
    "error": rr.TextLogLevel.ERROR,
}


def run_verdict(result: RunResult, dt: float) -> RunVerdict:
    """The verdict a recording opens on, from the run's result.

    Args:
        result: The finished run.
        dt: Control period [s].
    """
    s = result.summary()
    replans = "".join(
        f" Replanned at t={r['t']:.2f} s after {r['after']}: attempt {r['attempt']}."
        for r in s["replans"]
    )
    if result.success:
        place = s.get("place_error_m")
        text = (
            (f"Brick placed {place * 1000:.1f} mm from its target; " if place is not None else "")
            + f"max tool position error {s['max_position_error_m'] * 1000:.1f} mm, max joint "
            f"speed / limit {s['max_joint_speed_ratio']:.3f}, min singular value "
            f"{s['min_singular_value']:.3f}." + replans
        )
        return RunVerdict(True, None, text, result.ticks, result.sim_time_s, dt)
    text = result.failure_text or str(result.failure)
    reason = str(result.failure)
    text = text.removeprefix(f"{reason}: ") + (f" ({replans.strip()})" if replans else "")
    tick = result.failure_tick if result.failure_tick is not None else result.ticks
    t = result.failure_time_s if result.failure_time_s is not None else result.sim_time_s
    return RunVerdict(False, reason, text, tick, t, dt)


# ---------------------------------------------------------------------------- the plots


class Recorder:
    """Record a :class:`~pickplace.sim.loop.Simulation` to Rerun (see the module docstring).

    One recorder records one run. The constructor only checks its arguments; :meth:`open`
    (called by the runner once every input is validated, or else by :meth:`on_start`) takes
    the output path and reaches the viewer. So a run refused for bad input never touches a file.

    The file: encoded in memory (a :class:`rerun.BinaryStream`; a run is a few MB), written
    to a temporary file beside ``path`` when the run has finished (success, failure or
    interruption) and renamed onto ``path`` once it reads back complete (footer and summary).
    A run that crashed or could not write the file (disk full, file size limit) deletes it
    and leaves an older file at ``path`` as it was; a killed run leaves the path as it was.
    One writer per path (a lock beside it, see :mod:`pickplace.outfile`). Nothing of Rerun's
    own file writer is used: its thread can deadlock after a write error.

    The viewers: fed through relay processes (:mod:`pickplace.record.viewer`), so a viewer that
    freezes, is stopped or goes away never blocks or ends the run: it is given up, an event
    says so and the file recording continues. Problems of either kind are listed in
    :attr:`file_error` and :attr:`warnings` after the run.

    Args:
        path: ``.rrd`` file to write, or None.
        recording_id: Recording id, e.g. ``pick-place/iiwa14-wsg50/qp/seed-0``.
        spawn: Also spawn a Rerun viewer (or use the one on port :data:`SPAWN_PORT`) and
            stream to it.
        connect: Also stream to a viewer at this gRPC URL
            (e.g. ``rerun+http://127.0.0.1:9876/proxy``).
        flush_every: Ticks per ``send_columns`` batch (each batch is flushed). Every batch
            costs the same ~35 calls whatever its length, so longer batches record faster.
        flush_interval_s: Also send what is complete once this much wall time [s] has passed
            since the last batch.

    Raises:
        RecordingError: No sink was given.
        InvalidInputError: ``flush_every`` is not a positive integer, ``flush_interval_s`` is
            not a positive number, or ``connect`` is not a viewer URL.
    """

    def __init__(
        self,
        path: Path | None,
        *,
        recording_id: str,
        spawn: bool = False,
        connect: str | None = None,
        flush_every: int = 200,
        flush_interval_s: float = 0.25,
    ) -> None:
        if isinstance(flush_every, bool) or not isinstance(flush_every, int) or flush_every < 1:
            raise InvalidInputError(f"flush_every must be an integer >= 1, got {flush_every!r}")
        if not (isinstance(flush_interval_s, int | float) and flush_interval_s > 0):
            raise InvalidInputError(
                f"flush_interval_s must be a number > 0 [s], got {flush_interval_s!r}"
            )
        if path is None and not spawn and connect is None:
            raise RecordingError("a recording needs a file path, spawn=True or a connect URL")
        self.path = Path(path) if path is not None else None
        self.recording_id = recording_id
        self.spawn = spawn
        self.connect = parse_viewer_url(connect) if connect is not None else None
        self.flush_every = flush_every
        self.flush_interval_s = float(flush_interval_s)
        self.file_error: str | None = None  # why the file could not be written
        self.warnings: list[str] = []  # viewer problems (the run went on)
        self.written: Path | None = None  # the file, once it is in place
        self._last_send = time.perf_counter()
        self.rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
        self.rec.set_log_time_enabled(False)
        self.rec.set_log_tick_enabled(False)
        self._output = OutputFile(self.path) if self.path is not None else None
        self._file_bytes: rr.BinaryStream | None = None  # the file, encoded in memory
        self._viewer_bytes: rr.BinaryStream | None = None  # what the viewer relays receive
        self._relays: list[ViewerRelay] = []
        self._opened = False
        self._closed = False
        self._finished = False
        self._started = False
        self._sent = 0  # ticks already sent
        self._verdict_logged = False
        self._early_events: list[Event] = []
        self._moving: list[tuple[int, str]] = []  # (body id, entity path)
        self._replans = 0  # plans that replaced another (world/plan/replans/<n>)
        self._ik_status_names = ", ".join(f"{i} {s}" for i, s in enumerate(IK_STATUSES))

    # ------------------------------------------------------------------ lifecycle

    def open(self) -> None:
        """Take the output path, reach the viewers and open the sinks. Idempotent.

        Raises:
            OutputError: Another run writes the same path, the folder cannot be written, or a
                viewer does not answer; nothing is left behind.
            RecordingError: The recorder was closed.
        """
        if self._opened:
            return
        if self._closed:
            raise RecordingError("the recorder is closed; use one Recorder per run")
        sinks: list[Any] = []
        try:
            if self._output is not None:
                self._output.open()
                self._file_bytes = rr.binary_stream(recording=self.rec)
                sinks.append(self._file_bytes)
            addresses = []
            if self.spawn:
                addresses.append(spawn_viewer(SPAWN_PORT))
            if self.connect is not None:
                addresses.append(self.connect)
            for addr in addresses:
                self._relays.append(ViewerRelay(addr, self.recording_id))
            if self._relays:
                self._viewer_bytes = rr.binary_stream(recording=self.rec)
                sinks.append(self._viewer_bytes)
            self.rec.set_sinks(*sinks, default_blueprint=build_blueprint())
        except BaseException:
            self._discard()
            raise
        self._opened = True

    def __enter__(self) -> Recorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        """True once the stream has been closed (the file is in place, or was not kept)."""
        return self._closed

    def close(self) -> None:
        """End without a finished run: nothing is put in place (an older file is kept), the
        viewers are let go. Idempotent; does nothing after :meth:`on_finish`."""
        if not self._closed:
            self._discard()

    def _discard(self) -> None:
        self._closed = True
        with contextlib.suppress(RuntimeError):
            self.rec.disconnect()
        for relay in self._relays:
            relay.kill()
        if self._output is not None:
            self._output.discard()

    def _flush(self, run: Simulation | None) -> None:
        """Hand the batch's bytes to the viewers (the file's stay in memory until the end)."""
        if self._viewer_bytes is not None:
            try:
                data = self._viewer_bytes.read(flush=True, flush_timeout_sec=ENCODE_TIMEOUT_S)
            except RuntimeError as exc:  # the viewers miss this batch; the file does not
                data = None
                self.warnings.append(f"a batch for the viewer could not be encoded: {exc}")
            for relay in self._relays:
                relay.send(data or b"")
        self._check_viewers(run)

    def _file_failed(self, reason: str) -> None:
        assert self.path is not None
        self.file_error = f"cannot write the recording '{self.path}': {reason}; " + (
            "an older file there is unchanged" if self.path.exists() else "no file was left"
        )

    def _write_file(self) -> None:
        """Write the encoded recording to the temporary file (fsync'd on commit)."""
        assert self._output is not None and self._file_bytes is not None
        temp = self._output.temp
        assert temp is not None
        try:
            data = self._file_bytes.read(flush=True, flush_timeout_sec=ENCODE_TIMEOUT_S)
        except RuntimeError as exc:
            self._file_failed(f"it could not be encoded within {ENCODE_TIMEOUT_S:g} s ({exc})")
            return
        try:
            with open(temp, "wb") as f:
                f.write(data or b"")
        except OSError as exc:
            self._file_failed(exc.strerror or str(exc))

    def _check_viewers(self, run: Simulation | None) -> None:
        for relay in self._relays:
            if relay.lost is not None and not any(relay.addr.url in w for w in self.warnings):
                when = f"; noticed at t={run.ticks * run.dt:.2f} s" if run is not None else ""
                text = (
                    f"the viewer at {relay.addr.url} {relay.lost}{when}; streaming to it "
                    "stopped" + (", the recording file goes on" if self._output is not None else "")
                )
                self.warnings.append(text)
                relay.kill()
                if run is not None:
                    run.emit(EventKind.VIEWER, text, level="warn")

    def _finish(self, run: Simulation, *, interrupted: bool) -> None:
        """Hand the rest to the viewers, write the file, close the stream, let the viewers
        take the rest (briefly after an interrupt: whoever stops a run wants it to end), check
        the file and put it in place."""
        self._flush(run)
        if self._output is not None:
            self._write_file()
        self._closed = True
        with contextlib.suppress(RuntimeError):
            self.rec.disconnect()
        timeout = VIEWER_FINISH_AFTER_INTERRUPT_S if interrupted else FINISH_TIMEOUT_S
        for relay in self._relays:
            problem = relay.finish(timeout)
            if problem is not None:
                self.warnings.append(problem)
        self._check_viewers(None)
        if self._output is None:
            return
        temp = self._output.temp
        if self.file_error is None and temp is not None:
            problem = read_back_problem(temp, "summary")
            if problem is not None:
                self._file_failed(problem)
        if self.file_error is not None:
            self._output.discard()
            return
        try:
            self._output.commit()
        except OutputError as exc:
            self.file_error = str(exc)
            return
        self.written = self.path

    # ------------------------------------------------------------------ observer

    def on_start(self, run: Simulation) -> None:
        """Open (if not yet), then log the static scene, plan and plot styles."""
        self.open()
        self._started = True
        with deferred_interrupts():
            self._log_scene(run)
            self._log_plan(run)
            self._log_styles(run)
            for event in self._early_events:
                self._log_event(event.tick, event.t, event.level, event.text)
            self._early_events.clear()
            self._flush(run)

    def on_ticks(self, run: Simulation, start: int, end: int) -> None:
        """Send a batch once ``flush_every`` completed ticks are waiting, or once
        ``flush_interval_s`` has passed since the last batch."""
        if self._closed or end <= self._sent:
            return
        now = time.perf_counter()
        if end - self._sent >= self.flush_every or now - self._last_send >= self.flush_interval_s:
            with deferred_interrupts():
                self._send(run, end)
                self._flush(run)
            self._last_send = time.perf_counter()

    def on_event(self, run: Simulation, event: Event) -> None:
        """Log the event at its tick (events are rare: plain ``log``)."""
        if self._closed:
            return
        if not self._started:
            self._early_events.append(event)  # e.g. scene warnings emitted before the run
            return
        self._log_event(event.tick, event.t, event.level, event.text)
        if event.kind is EventKind.VERDICT:
            self._verdict_logged = True
        elif event.kind is EventKind.REPLAN:
            self._log_replan(run, event)

    def on_finish(self, run: Simulation, result: RunResult) -> None:
        """Send the rest of the log, the summary and the verdict, close the stream and put the
        file in place."""
        if self._closed:
            return
        try:
            if self._started:
                last = min(int(run.ticks), len(run.log.t))
                self._send(run, last)
                if last > 1:
                    self._send_limit_rows(run.log, last - 1)
            summary = result.summary()
            if summary.get("recording") is None and self.path is not None:
                summary["recording"] = str(self.path)
            text = json.dumps(summary, indent=2, default=str)
            self.rec.log(
                "summary",
                rr.TextDocument(f"```json\n{text}\n```", media_type=rr.MediaType.MARKDOWN),
                static=True,
            )
            if not self._verdict_logged:
                verdict = "success" if result.success else f"failure: {result.failure}"
                level = "info" if result.success else "error"
                self._log_event(result.ticks, result.sim_time_s, level, f"verdict: {verdict}")
                self._verdict_logged = True
            self._log_verdict(run, result)
            self._finish(run, interrupted=str(result.failure) == "interrupted")
            self._finished = True
        finally:
            if not self._finished:
                self._discard()

    # ------------------------------------------------------------------ the answer

    def _log_verdict(self, run: Simulation, result: RunResult) -> None:
        """The verdict panel's text and the blueprint the file opens on (cursor at the failure
        tick or the end, axes fitted to the data), sent after everything else so that it is
        the one a viewer makes active."""
        verdict = run_verdict(result, run.dt)
        self.rec.log(
            "verdict",
            rr.TextDocument(verdict.markdown(), media_type=rr.MediaType.MARKDOWN),
            static=True,
        )
        last = min(int(run.ticks), len(run.log.t))
        ranges = {}
        if last > 0:
            rows = slice(0, last)
            for plot in PLOTS:
                limits = [] if plot.limits is None else plot.limits.values(run.scene)
                fitted = y_range_of(plot.values(run.log, rows), np.ravel(limits).tolist())
                if fitted is not None:
                    ranges[plot.path] = fitted
        self.rec.send_blueprint(
            build_blueprint(verdict, ranges), make_active=True, make_default=True
        )

    # ------------------------------------------------------------------ static content

    def _log_scene(self, run: Simulation) -> None:
        model, data, rec = run.model, run.data, self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        bodies = element_names(model, mujoco.mjtObj.mjOBJ_BODY, model.nbody, "body")
        geoms = element_names(model, mujoco.mjtObj.mjOBJ_GEOM, model.ngeom, "geom")
        body_paths = ["world/static"] + [f"world/bodies/{path_part(n)}" for n in bodies[1:]]
        used: set[int] = set()
        for g in range(model.ngeom):
            rgba = geom_rgba(model, g)
            if model.geom_group[g] > 2 or rgba[3] <= 0.0:
                continue
            shape = geom_archetype(model, g, rgba)
            if shape is None:
                continue
            b = int(model.geom_bodyid[g])
            used.add(b)
            path = f"{body_paths[b]}/{path_part(geoms[g])}"
            pose = rr.Transform3D(
                translation=model.geom_pos[g], quaternion=quat(model.geom_quat[g])
            )
            rec.log(path, pose, shape, static=True)
        self._moving = []
        for b in range(1, model.nbody):
            if model.body_weldid[b] != 0 or model.body_mocapid[b] >= 0:
                self._moving.append((b, body_paths[b]))
            elif b in used:
                pose = rr.Transform3D(translation=data.xpos[b], quaternion=quat(data.xquat[b]))
                rec.log(body_paths[b], pose, static=True)
        for name, length in TOOL_AXES.items():
            rec.log(f"world/tool/{name}", rr.TransformAxes3D(length), static=True)
        rec.log(
            "world/tool/manipulability_ellipsoid",
            rr.Ellipsoids3D.from_fields(
                colors=[[0.2, 0.6, 1.0, 0.25]], fill_mode=SOLID, line_radii=[0.0005]
            ),
            static=True,
        )

    def _log_plan(self, run: Simulation) -> None:
        rec, traj = self.rec, run.task.trajectory
        path = traj.sample_path(400)
        rec.log(
            "world/plan/path",
            rr.LineStrips3D([path], colors=[[0.1, 0.75, 0.95]], radii=[0.003]),
            static=True,
        )
        # Keyframes whose labels would overlap in the opening view (pick, settle, grip-closed
        # at one position; pre-pick under lift) share one label: the first of a group shows
        # all the names, the others none (blueprint.label_groups).
        names: list[str] = []
        for i, kf in enumerate(traj.keyframes):
            names.append(kf.name if kf.name not in names else f"{kf.name}-{i}")
        poses = [np.asarray(kf.X_WG.wxyz_xyz) for kf in traj.keyframes]
        groups = label_groups(names, np.array([p[4:] for p in poses]))
        leader = {g[0]: g for g in groups}
        for i, (name, wxyz_xyz) in enumerate(zip(names, poses, strict=True)):
            group = [names[j] for j in leader.get(i, [])]
            rec.log(
                f"world/plan/keyframes/{path_part(name)}",
                rr.Transform3D(translation=wxyz_xyz[4:], quaternion=quat(wxyz_xyz[:4])),
                rr.TransformAxes3D(0.05),
                rr.Points3D(
                    [[0.0, 0.0, 0.0]],
                    radii=[0.008],
                    colors=[[1.0, 0.85, 0.1]],
                    labels=[" / ".join(group) if group else name],
                    show_labels=bool(group),
                ),
                static=True,
            )
        bin_ = run.scene.target_bin
        height = bin_.wall_top_z - bin_.floor_top_z
        center = bin_.center_W + np.array([0.0, 0.0, 0.5 * height])
        half = [bin_.inner_half_extents[0], bin_.inner_half_extents[1], 0.5 * height]
        rec.log(
            "world/plan/target_bin",
            rr.Boxes3D(
                half_sizes=[half],
                centers=[center],
                quaternions=[xyzw(bin_.X_WB.rotation().wxyz)],
                colors=[[0.1, 0.85, 0.2]],
                radii=[0.003],
                labels=[f"target: {bin_.name}"],
                show_labels=False,  # the keyframe labels above it say enough
            ),
            static=True,
        )
        self._log_rejected(run)

    def _log_replan(self, run: Simulation, event: Event) -> None:
        """The plan that has just replaced the one executed: its tool path, from the event's
        time on (a plan carrying nothing, the stop after a failed attempt, in orange)."""
        self._replans += 1
        plan = run.plan
        colour = [1.0, 0.55, 0.1] if plan.phases is None else [0.2, 0.85, 0.35]
        self.rec.set_time("sim_time", duration=to_duration(np.array([event.t]))[0])
        self.rec.set_time("tick", sequence=int(event.tick))
        self.rec.log(
            f"world/plan/replans/{self._replans}/path",
            rr.LineStrips3D(
                [plan.trajectory.sample_path(200)],
                colors=[colour],
                radii=[0.003],
                labels=[f"plan {self._replans + 1} from t={event.t:.2f} s"],
            ),
        )

    def _log_rejected(self, run: Simulation) -> None:
        """Each candidate plan the planner rejected: its path, thin and grey, and a red marker
        where its first problem happened (contact point, limited joint or tool), labelled."""
        planning = run.task.planning
        if planning is None:
            return
        for i, c in enumerate(planning.candidates):
            problem = c.preflight.problem
            if problem is None:
                continue
            base = f"world/plan/rejected/{i}"
            self.rec.log(
                f"{base}/path",
                rr.LineStrips3D(
                    [c.plan.trajectory.sample_path(200)],
                    colors=[[0.55, 0.55, 0.6]],
                    radii=[0.0015],
                ),
                static=True,
            )
            self.rec.log(
                f"{base}/problem",
                rr.Points3D(
                    [problem.point_W],
                    radii=[0.012],
                    colors=[[0.95, 0.15, 0.15]],
                    labels=[f"{c.label}: {problem.kind} at t={problem.t:.2f} s"],
                ),
                static=True,
            )

    def _log_styles(self, run: Simulation) -> None:
        """Log the static line style of every plot of :data:`~pickplace.record.blueprint.PLOTS` and
        of its limit lines."""
        for series in (*PLOTS, *LIMIT_LINES):
            self.rec.log(series.path, series.style(run.scene), static=True)

    # ------------------------------------------------------------------ tick data

    def _log_event(self, tick: int, t: float, level: str, text: str) -> None:
        self.rec.set_time("sim_time", duration=to_duration(np.array([t]))[0])
        self.rec.set_time("tick", sequence=int(tick))
        self.rec.log("events", rr.TextLog(text, level=LEVELS.get(level, rr.TextLogLevel.INFO)))

    def _send(self, run: Simulation, end: int) -> None:
        """Send rows ``[self._sent, end)`` of ``run.log`` as columns."""
        start = self._sent
        if end <= start:
            return
        self._sent = end
        log: TickLog = run.log
        sl = slice(start, end)
        times = [
            rr.TimeColumn("sim_time", duration=to_duration(log.t[sl])),
            rr.TimeColumn("tick", sequence=np.arange(start, end, dtype=np.int64)),
        ]
        send = self.rec.send_columns

        for b, path in self._moving:
            send(path, times, transform_columns(log.body_pos[sl, b], log.body_quat[sl, b]))
        send(
            "world/tool/planned", times, transform_columns(log.p_WG_plan[sl], log.quat_WG_plan[sl])
        )
        send(
            "world/tool/commanded", times, transform_columns(log.p_WG_cmd[sl], log.quat_WG_cmd[sl])
        )
        send("world/tool/actual", times, transform_columns(log.p_WG[sl], log.quat_WG[sl]))

        half = ELLIPSOID_SCALE * log.sigma_t[sl]
        half[~np.isfinite(half)] = 0.0
        send(
            "world/tool/manipulability_ellipsoid",
            times,
            rr.Ellipsoids3D.columns(
                half_sizes=half, centers=log.p_WG[sl], quaternions=xyzw(log.quat_t[sl])
            ),
        )

        for plot in PLOTS:
            send(plot.path, times, scalar_columns(plot.values(log, sl)))

        if start == 0:
            self._send_limit_rows(log, 0)

    def _send_limit_rows(self, log: TickLog, tick: int) -> None:
        """The constant limit lines get a row at the first and at the last tick only."""
        times = [
            rr.TimeColumn("sim_time", duration=to_duration(log.t[tick : tick + 1])),
            rr.TimeColumn("tick", sequence=np.array([tick], dtype=np.int64)),
        ]
        for lines in LIMIT_LINES:
            row = np.asarray(lines.values(log.scene), dtype=np.float64)
            self.rec.send_columns(lines.path, times, scalar_columns(row[None, :]))
