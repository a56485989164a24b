"""The session: owns the driver and runs the fixed-rate control loop off the asyncio event loop.

One tick: read the driver -> odometry -> (SLAM / localization) -> pick the command for the mode
(teleop, navigator, behaviour) -> safety and limits -> ``driver.command`` -> publish a snapshot.
Other threads talk to the loop through short locked setters (teleop command, mode requests, e-stop);
nothing in a tick waits on the database, the planner, the viewer or a client.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np

from app.bus import Snapshot, SnapshotBus
from app.fault_monitor import FaultMonitor, FaultMonitorOptions
from app.limits import (
    CommandRefused,
    SpeedLimit,
    apply_speed_limit,
    clamp_speed,
    limit_acceleration,
    ramp_duration,
    sanity_check,
)
from app.modes import LIDAR_MODES, Mode, ModeMachine, no_lidar_reason
from app.odometry_history import OdometryHistory
from nav.types import ZERO_TWIST, LaserScan, OccupancyGrid, Pose2D, Twist2D
from robot.base import Driver, LinkState, SensorFrame
from robot.clock import Clock, RealClock
from robot.odometry import WheelOdometry

log = logging.getLogger("navdeck.session")

TELEOP_REARM_REASON = (
    "release the controls first: after an e-stop or a fault reset the robot moves only on a fresh "
    "command (key released and pressed again, joystick back through zero)"
)


class Stage(Protocol):
    """A pipeline stage run by the control loop (SLAM, localization, costmaps, navigation...).

    ``tick`` must be quick: heavy work goes to ``session.workers`` and comes back on a later tick.
    ``snapshot_fields`` returns Snapshot fields to publish (``path``, ``goal``, ``particles``,
    ``behavior``, ``local_plan``, and an ``extras`` dict merged into the snapshot's extras)."""

    def tick(self, session: Session, frame: SensorFrame, now: float) -> None: ...

    def snapshot_fields(self, session: Session) -> dict[str, Any] | None: ...

    def close(self) -> None: ...


CommandSource = Callable[[float], "Twist2D | None"]
SafetyFilter = Callable[[Twist2D, SensorFrame], "tuple[Twist2D, str | None]"]


@dataclass(frozen=True)
class SessionOptions:
    rate_hz: float = 20.0  # control loop rate
    deadman_timeout: float = 0.5  # s without a teleop command -> stop
    lidar_timeout: float = 1.5  # s without a scan while moving the robot -> FAULT
    trail_length: int = 2000  # poses kept for the odometry trail
    trail_min_step: float = 0.02  # m between trail points
    odom_history: float = 2.0  # s of (stamp, odom pose) kept to pair scans with odometry at their stamp
    faults: FaultMonitorOptions = field(default_factory=FaultMonitorOptions)  # garbage/slip/imu/overrun
    # Nice value asked for the control-loop thread (Linux, per thread). Below 0 needs root or
    # CAP_SYS_NICE (systemd: AmbientCapabilities=CAP_SYS_NICE); without it the thread keeps the
    # process's. It lets the loop's wake-up preempt the web server's threads and the other
    # processes on a small robot computer, as a ROS 2 controller's real-time thread would.
    loop_nice: int = -10


@dataclass
class TeleopState:
    command: Twist2D = ZERO_TWIST
    stamp: float = -math.inf
    client: str | None = None


@dataclass
class LoopStats:
    """Control-loop timing: lateness of each tick's start against its schedule and tick duration."""

    lateness_ms: deque = field(default_factory=lambda: deque(maxlen=2000))
    duration_ms: deque = field(default_factory=lambda: deque(maxlen=2000))
    period_ms: deque = field(default_factory=lambda: deque(maxlen=2000))  # start to start
    overruns: int = 0
    ticks: int = 0
    nice: int | None = None  # the control thread's nice value (None: not known)

    def summary(self) -> dict[str, float]:
        late = np.fromiter(tuple(self.lateness_ms), float)
        dur = np.fromiter(tuple(self.duration_ms), float)
        if late.size == 0 or dur.size == 0:
            return {"ticks": self.ticks}
        return {
            "ticks": self.ticks,
            "overruns": self.overruns,
            **({"nice": self.nice} if self.nice is not None else {}),
            "lateness_p50_ms": float(np.percentile(late, 50)),
            "lateness_p99_ms": float(np.percentile(late, 99)),
            **self._period_summary(),
            "tick_p50_ms": float(np.percentile(dur, 50)),
            "tick_p99_ms": float(np.percentile(dur, 99)),
        }

    def _period_summary(self) -> dict[str, float]:
        period = np.fromiter(tuple(self.period_ms), float)
        if period.size == 0:
            return {}
        p50, p99 = np.percentile(period, [50, 99])
        return {"period_p50_ms": float(p50), "period_p99_ms": float(p99)}


class Session:
    def __init__(
        self,
        driver: Driver,
        *,
        clock: Clock | None = None,
        grid: OccupancyGrid | None = None,
        start_pose: Pose2D | None = None,
        options: SessionOptions | None = None,
        robot_name: str = "navdeck",
    ) -> None:
        self.driver = driver
        self.profile = driver.profile
        self.clock: Clock = clock or RealClock()
        options = options or SessionOptions()
        start_pose = start_pose or Pose2D()
        self.options = options
        self.robot_name = robot_name
        self.period = 1.0 / options.rate_hz
        self.bus = SnapshotBus()
        self.events: deque[dict] = deque(maxlen=500)  # recent events for the UI and the recorder
        self.event_listeners: list[Callable[[dict], None]] = []
        self.modes = ModeMachine(on_change=self._on_mode_change)
        self.has_lidar = bool(getattr(driver, "has_lidar", True))  # test doubles may not say
        if not self.has_lidar:
            for mode in LIDAR_MODES:
                self.modes.set_unavailable(frozenset({mode}), no_lidar_reason(mode.value))
        self.odometry = WheelOdometry(self.profile)
        self.grid = grid
        self.grid_version = 1 if grid is not None else 0
        self.map_to_odom = start_pose  # odom starts at the start pose until localization says otherwise
        self.pose = start_pose
        self.odom_pose = Pose2D()
        self.odom_history = OdometryHistory(options.odom_history)  # (stamp, odom pose) of each update
        self.velocity = ZERO_TWIST
        self.wheel_slip = False
        self.last_command = ZERO_TWIST
        self.last_clamped: tuple[str, ...] = ()
        self.last_scan: LaserScan | None = None
        self.last_scan_time = -math.inf
        self.battery_v: float | None = None
        self.link_state = LinkState.OK
        self.link_reason = ""
        self.fault: str | None = None
        self.lidar_fault: str | None = None  # what is wrong with the lidar right now (status Link row)
        self.estop_latched = False
        self.collisions = 0
        self.distance_travelled = 0.0
        self.stats = LoopStats()
        self.fault_monitor = FaultMonitor(
            self.period, options.faults, expected_beams=self.profile.lidar.beams
        )
        self._teleop = TeleopState()
        # Clients whose latest teleop input is a motion (a key held, a stick deflected), and those of
        # them disarmed by an e-stop, fault or reset: they drive again only after a zero input, so a
        # key held through a reset does not move the robot the moment it is re-armed.
        self._teleop_holding: set[str] = set()
        self._teleop_disarmed: set[str] = set()
        self._lock = threading.Lock()
        self._trail: deque[tuple[float, float]] = deque(maxlen=options.trail_length)
        # the trail as an array, rebuilt only when it changes: one copy per new point, not per tick
        # (the 3D view also redraws the trail only when the snapshot's array is a new object)
        self._trail_array: np.ndarray | None = None
        self._seq = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.stages: list[Stage] = []
        self.command_sources: dict[Mode, CommandSource] = {}
        # True while a navigation request drives in MAPPING (navigate while mapping, exploration):
        # the MAPPING command source then drives instead of teleop.
        self.mapping_autonomy: Callable[[], bool] | None = None
        # Last word before the driver, below every planner: (command, frame) -> (command, reason or None).
        self.safety: SafetyFilter | None = None
        self._last_frame: SensorFrame | None = None
        self.safety_stop: str | None = None
        # A speed zone's limit where the robot is (set by the zones stage each tick), for every mode
        self.speed_limit: SpeedLimit | None = None
        # Workers are started from the loop thread: back to the process's priority, not the loop's.
        self.workers = ThreadPoolExecutor(
            max_workers=2, thread_name_prefix="worker", initializer=_process_priority_for_this_thread
        )
        self._reset_driver = False
        self._wake = threading.Event()
        # Reflex path: a teleop command is written at once, not at the next tick. From the caller's
        # thread if the driver takes commands from any thread (no hand-over to a loop thread that may
        # be mid-tick), else from the loop thread, woken. One command computed and written at a time.
        self._command_lock = threading.RLock()
        self._reflex_in_caller = bool(getattr(driver, "command_thread_safe", False))
        self._ramp_end = math.inf  # when a ramp the reflex started reaches its command (loop sends it)
        self._last_send_t = self.clock.now()
        self.started_at = self.clock.now()

    # ------------------------------------------------------------------ commands from other threads
    def set_teleop(self, cmd: Twist2D, client: str) -> bool:
        """Store an operator's velocity command (teleop websocket). Applied while the mode allows it,
        and sent at once (reflex path) so it reaches the driver without waiting for the next tick.

        A command beyond the sanity bound (``app.limits.sanity_check``: 2x the profile's limits) is
        refused: the robot is stopped (teleop zeroed) and ``CommandRefused`` raised for the caller
        to report. Commands a little over the limits are clamped later, and reported, as usual.
        False (ignored, ``TELEOP_REARM_REASON``): a motion command before the zero command that
        re-arms teleop after an e-stop, fault or reset."""
        self.check_teleop(cmd, client)
        if not self.teleop_input(cmd, client):
            return False
        self._store_teleop(cmd, client)
        return True

    def check_teleop(self, cmd: Twist2D, client: str) -> None:
        """Raise ``CommandRefused`` for a command beyond the sanity bound, after stopping the robot
        (callers may check before acting on a command in other ways, e.g. a mode switch)."""
        try:
            sanity_check(cmd, self.profile.limits, self.profile.is_omni)
        except CommandRefused as exc:
            self._store_teleop(ZERO_TWIST, client)
            last = self.events[-1] if self.events else None
            t = self.clock.now() - self.started_at
            # a client repeating the mistake at 20 Hz gets an error per command, the run one event a second
            if not (
                last and last["type"] == "refused" and last.get("what") == "teleop" and t - last["t"] < 1.0
            ):
                self.add_event("refused", what="teleop", reason=str(exc))
            raise

    def teleop_engaged(self, now: float) -> bool:
        """An operator is driving by hand right now: a fresh (within the deadman time) non-zero
        teleop command from an armed client."""
        with self._lock:
            tele = self._teleop
        return not tele.command.is_zero() and now - tele.stamp <= self.options.deadman_timeout

    @property
    def teleop_command(self) -> Twist2D:
        """The operator command held for the loop (before limits; zeroed by refusals and stops)."""
        return self._teleop.command

    def _store_teleop(self, cmd: Twist2D, client: str) -> None:
        with self._lock:
            self._teleop = TeleopState(cmd, self.clock.now(), client)
        if self._reflex_in_caller and self._thread is not None and not self.clock.is_virtual:
            self._reflex(schedule_ramp_end=True)
        self._wake.set()

    def teleop_input(self, cmd: Twist2D, client: str) -> bool:
        """Note an operator's latest input, whether or not the mode lets it drive; False while the
        client is disarmed (``TELEOP_REARM_REASON``): a motion held since an e-stop, fault or reset."""
        with self._lock:
            if cmd.is_zero():
                self._teleop_holding.discard(client)
                self._teleop_disarmed.discard(client)
                return True
            self._teleop_holding.add(client)
            return client not in self._teleop_disarmed

    def _disarm_teleop(self) -> None:
        """Every client holding a motion must let go before it drives again (call under ``_lock``)."""
        self._teleop_disarmed |= self._teleop_holding

    def stop_teleop(self, client: str | None = None) -> None:
        with self._lock:
            if client is None or self._teleop.client in (client, None):
                self._teleop = TeleopState(ZERO_TWIST, self.clock.now(), None)

    def request_mode(self, mode: str) -> Mode:
        """Operator mode request; raises app.modes.TransitionRefused."""
        return self.modes.request(mode)

    def estop(self, source: str = "operator") -> None:
        """Latch the e-stop. The driver is stopped at the latest at the next tick."""
        with self._lock:
            self.estop_latched = True
            self._teleop = TeleopState()
            self._disarm_teleop()
        self.modes.enter(Mode.ESTOP, f"e-stop by {source}")

    def reset(self) -> Mode:
        """Release the e-stop latch or clear a fault (refused while the fault is still present)."""
        blocked = self._fault_still_present()
        mode = self.modes.reset(blocked_by=blocked)
        with self._lock:
            self.estop_latched = False
            self.fault = None
            self._teleop = TeleopState()
            self._disarm_teleop()  # also a motion held during the e-stop: only a zero input re-arms
        self.fault_monitor.on_reset()
        self._reset_driver = True
        return mode

    def add_stage(self, stage: Stage) -> None:
        """Add a pipeline stage: ``tick`` runs after odometry each control period (in order added)."""
        self.stages.append(stage)

    def set_command_source(self, mode: Mode, source: CommandSource) -> None:
        """Who drives in ``mode``: ``source(now)`` returns a Twist2D, or None to stop at once."""
        self.command_sources[mode] = source

    # ------------------------------------------------------------------ loop
    def start(self) -> None:
        if self._thread is not None:
            return
        self._stop.clear()
        if not self.clock.is_virtual:
            # The loop shares the GIL with the web server's event loop: with CPython's default 5 ms
            # switch interval every GIL hand-back inside a tick can cost the loop up to 5 ms under load.
            sys.setswitchinterval(min(sys.getswitchinterval(), 0.001))
        self._thread = threading.Thread(target=self._run, name="control-loop", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        for stage in self.stages:
            try:
                stage.close()
            except Exception:
                log.exception("stage close failed")
        self.workers.shutdown(wait=False, cancel_futures=True)
        try:
            self.driver.stop()
        finally:
            self.driver.close()

    def _run(self) -> None:
        if not self.clock.is_virtual:
            self.stats.nice = _prioritize_this_thread(self.options.loop_nice)
        next_t = self.clock.now()
        prev_start: float | None = None
        while not self._stop.is_set():
            start = self.clock.now()
            self.stats.lateness_ms.append(max(0.0, (start - next_t) * 1e3))
            if prev_start is not None:
                self.stats.period_ms.append((start - prev_start) * 1e3)
                overrun = self.fault_monitor.check_period(start - prev_start)
                if overrun is not None and self.fault is None:
                    self._enter_fault(overrun)  # this tick's command is then the stop
            prev_start = start
            t0 = time.perf_counter()
            try:
                self.step()
            except Exception as exc:  # a bug in a stage must stop the robot, not kill the loop silently
                log.exception("control tick failed")
                self._enter_fault(f"internal error: {exc}")
                self._safe_stop()
            self.stats.duration_ms.append((time.perf_counter() - t0) * 1e3)
            next_t += self.period
            now = self.clock.now()
            if now > next_t + self.period:  # overran by a whole period: skip, don't try to catch up
                self.stats.overruns += 1
                next_t = now
            self._sleep_until(next_t)

    def _sleep_until(self, next_t: float) -> None:
        """Wait for the next tick. Reflex path: a fresh operator command is sent at once (by its
        caller's thread, or here when the driver wants commands from the loop thread only), and the
        end of the acceleration ramp it starts at the time the limit allows, so teleop latency is
        not a whole period."""
        if self.clock.is_virtual:
            self.clock.sleep_until(next_t, self._stop)
            return
        while not self._stop.is_set():
            now = self.clock.now()
            if now >= next_t:
                return
            if self._wake.wait(min(next_t, self._ramp_end) - now):
                self._wake.clear()  # a teleop command: sent here unless its caller sent it already
                if not self._reflex_in_caller and not self._stop.is_set():
                    self._reflex(schedule_ramp_end=True)
            elif self.clock.now() >= self._ramp_end and not self._stop.is_set():
                # the ramp's end is sent when the acceleration limit allows, not at the next tick
                # (one extra frame at most per operator message)
                self._reflex(schedule_ramp_end=False)

    def _reflex(self, schedule_ramp_end: bool) -> None:
        """Send the command for the mode now (the first ramp step towards it); with
        ``schedule_ramp_end`` note when the acceleration ramp will reach it for the loop to send."""
        with self._command_lock:
            self._ramp_end = math.inf
            try:
                cmd = self._choose_command(self.clock.now())
                self._send(cmd)
            except Exception as exc:
                log.exception("reflex command failed")
                self._enter_fault(f"internal error: {exc}")
                self._safe_stop()
                return
            if cmd is None or not schedule_ramp_end:
                return
            target, _ = clamp_speed(cmd, self.profile.limits, self.profile.is_omni)
            left = ramp_duration(target, self.last_command, self.profile.limits)
            if left > 1e-9:  # 0.5 ms of slack: the ramp is certainly complete when its end is sent
                self._ramp_end = self._last_send_t + left + 5e-4

    def run_for(self, seconds: float) -> None:
        """Step the loop synchronously for ``seconds`` of clock time (virtual-clock tests and benches)."""
        n = max(1, round(seconds / self.period))
        for _ in range(n):
            self.clock.sleep_until(self.clock.now() + self.period)
            self.step()

    def step(self) -> None:
        now = self.clock.now()
        self.stats.ticks += 1
        frame = self._screen_scan(self.driver.read())
        self._last_frame = frame
        self._ingest(frame, now)
        for stage in self.stages:
            stage.tick(self, frame, now)
        with self._command_lock:  # the reflex path may write from another thread
            cmd = self._choose_command(now)
            self._send(cmd)
        self._publish(now)

    # ------------------------------------------------------------------ tick stages
    def _screen_scan(self, frame: SensorFrame) -> SensorFrame:
        """Sanitize the scan's bad beams (NaN) or withhold a garbage scan from every consumer."""
        if frame.scan is None:
            return frame
        clean, _ = self.fault_monitor.check_scan(frame.scan)
        return frame if clean is frame.scan else replace(frame, scan=clean)

    def _ingest(self, frame: SensorFrame, now: float) -> None:
        motion_fault = None
        if frame.ticks is not None:
            prev = self.odom_pose
            odo = self.odometry.update(frame.ticks, frame.imu)
            self.odom_pose, self.velocity, self.wheel_slip = odo.pose, odo.twist, odo.slipping
            self.odom_history.add(odo.stamp, odo.pose)
            self.distance_travelled += prev.distance_to(self.odom_pose)
            motion_fault = self.fault_monitor.check_motion(odo)
        self.pose = self.map_to_odom.compose(self.odom_pose)
        if (
            not self._trail
            or math.hypot(self.pose.x - self._trail[-1][0], self.pose.y - self._trail[-1][1])
            >= self.options.trail_min_step
        ):
            self._trail.append((self.pose.x, self.pose.y))
            self._trail_array = None
        if frame.scan is not None:
            self.last_scan = frame.scan
            self.last_scan_time = now
        if frame.battery_v is not None:
            self.battery_v = frame.battery_v
        if frame.collision:
            self.collisions += 1
            self.add_event("collision", pose=[self.pose.x, self.pose.y, self.pose.theta])
        self.link_state, self.link_reason = frame.link.state, frame.link.reason
        bad_scans = self.fault_monitor.lidar_reason()  # garbage or stuck frames
        # what is wrong with the lidar now: the driver's word, garbage or stuck frames, silence
        self.lidar_fault = frame.lidar_fault or bad_scans or self._lidar_silence(now)
        # garbage before silence: withheld garbage scans also make the lidar look silent after a while
        fault = frame.fault or bad_scans or self._fault_condition(now) or motion_fault
        if fault is not None and self.fault is None:
            self._enter_fault(fault)
        elif fault is not None and fault != self.fault and self.modes.mode == Mode.FAULT:
            # the cause changed while faulted (e.g. a port came back reporting a health error): show the
            # present cause, which is what blocks a reset
            with self._lock:
                self.fault = fault
            self.modes.reason = fault

    def _choose_command(self, now: float) -> Twist2D | None:
        """The command for this tick before limits; None means stop now (no ramp)."""
        mode = self.modes.mode
        if self.estop_latched or mode in (Mode.ESTOP, Mode.FAULT) or self.fault is not None:
            return None
        if mode == Mode.MAPPING and self.mapping_autonomy is not None and self.mapping_autonomy():
            source = self.command_sources.get(Mode.MAPPING)
            if source is not None:
                return source(now)
        if mode in (Mode.TELEOP, Mode.MAPPING):
            with self._lock:
                tele = self._teleop
            if now - tele.stamp > self.options.deadman_timeout:
                return ZERO_TWIST
            return tele.command
        source = self.command_sources.get(mode)
        if source is not None:
            return source(now)
        return ZERO_TWIST

    def _send(self, cmd: Twist2D | None) -> None:
        if self._reset_driver:
            self._reset_driver = False
            self.driver.reset()
        if cmd is None:
            self._safe_stop()
            return
        now = self.clock.now()
        dt = self.period if self.clock.is_virtual else min(max(now - self._last_send_t, 1e-3), self.period)
        self._last_send_t = now
        limited, clamped = clamp_speed(cmd, self.profile.limits, self.profile.is_omni)
        limited, zoned = apply_speed_limit(limited, self.speed_limit)
        if zoned:
            clamped = (*clamped, "speed_limit")
        limited = limit_acceleration(limited, self.last_command, self.profile.limits, dt)
        if self.safety is not None and self._last_frame is not None:
            # after the ramp: a safety stop is immediate, never smoothed away
            limited, self.safety_stop = self.safety(limited, self._last_frame)
        self.last_clamped = clamped
        self.last_command = limited
        self.driver.command(limited)

    def _safe_stop(self) -> None:
        with self._command_lock:  # after a reflex write in flight, never before it
            self.last_command = ZERO_TWIST
            self.last_clamped = ()
            if self.estop_latched:
                self.driver.estop()
            else:
                self.driver.stop()

    def _publish(self, now: float) -> None:
        self._seq += 1
        fields: dict = {"extras": {"footprint": self.profile.footprint_polygon()}}
        for stage in self.stages:
            extra = stage.snapshot_fields(self)
            if extra:
                extras = extra.pop("extras", None)
                fields.update(extra)
                if extras:
                    fields["extras"].update(extras)
        snap = Snapshot(
            stamp=now,
            seq=self._seq,
            mode=self.modes.mode.value,
            pose=self.pose,
            odom_pose=self.odom_pose,
            velocity=self.velocity,
            command=self.last_command,
            clamped=self.last_clamped,
            scan=self.last_scan,
            laser_pose=Pose2D(
                self.profile.lidar.mount_x, self.profile.lidar.mount_y, self.profile.lidar.mount_yaw
            ),
            trail=self._trail_points(),
            grid=self.grid,
            grid_version=self.grid_version,
            health=self.health(now),
            estop=self.estop_latched,
            fault=self.fault,
            **fields,
        )
        self.bus.publish(snap)

    # ------------------------------------------------------------------ state helpers
    def health(self, now: float | None = None) -> dict:
        now = self.clock.now() if now is None else now
        batt = self.battery_v
        pct = None
        if batt is not None:
            full, empty = self.profile.battery_full_v, self.profile.battery_empty_v
            pct = float(np.clip((batt - empty) / (full - empty) * 100.0, 0.0, 100.0))
        return {
            "link": self.link_state.value,
            "link_reason": self.link_reason,
            "lidar": self.has_lidar,
            "lidar_fault": self.lidar_fault,
            "battery_v": batt,
            "battery_pct": pct,
            "scan_age_s": None
            if not math.isfinite(self.last_scan_time)
            else round(now - self.last_scan_time, 3),
            "loop": self.stats.summary(),
            "collisions": self.collisions,
            "fault": self.fault,
            # the fault latched but its cause is gone: a reset will be accepted (the dashboard says so)
            "fault_cleared": self.fault is not None and self._fault_still_present() is None,
        }

    def restart_trail(self) -> None:
        """Forget the trail (loop thread only): the pose jumped to a new estimate or map frame, and the
        old points would draw a line the robot never drove."""
        self._trail.clear()
        self._trail_array = None

    def _trail_points(self) -> np.ndarray | None:
        if not self._trail:
            return None
        if self._trail_array is None:
            self._trail_array = np.asarray(self._trail)
            self._trail_array.flags.writeable = False  # shared by every snapshot until the next point
        return self._trail_array

    def set_grid(self, grid: OccupancyGrid | None) -> None:
        self.grid = grid
        self.grid_version += 1

    def add_event(self, type_: str, **payload) -> None:
        """Record an event stamped ``t`` = seconds since the session started, on the session clock.
        The stamp is the session's own: a payload ``t`` (e.g. a RecoveryEvent's raw clock reading,
        monotonic seconds since boot on a real clock) never replaces it (issue 17 item 4)."""
        payload.pop("t", None)
        ev = {"t": round(self.clock.now() - self.started_at, 3), "type": type_, **payload}
        self.events.append(ev)
        for listener in list(self.event_listeners):
            try:
                listener(ev)
            except Exception:
                log.exception("event listener failed")

    def _enter_fault(self, reason: str) -> None:
        with self._lock:
            self.fault = reason
            self._teleop = TeleopState()
            self._disarm_teleop()
        self.modes.enter(Mode.FAULT, reason)

    def _fault_condition(self, now: float) -> str | None:
        """A fault that holds right now (link lost, lidar silent), or None."""
        if self.link_state == LinkState.LOST:
            return f"link lost: {self.link_reason or 'no telemetry'}"
        return self._lidar_silence(now)

    def _lidar_silence(self, now: float) -> str | None:
        """``lidar: no scan for N s`` when an expected lidar fell silent (never without a lidar)."""
        silent = now - max(self.last_scan_time, self.started_at)
        if self.has_lidar and silent > self.options.lidar_timeout:
            return f"lidar: no scan for {silent:.1f} s"
        return None

    def _fault_still_present(self) -> str | None:
        driver_fault = self._last_frame.fault if self._last_frame is not None else None
        return driver_fault or self.fault_monitor.present() or self._fault_condition(self.clock.now())

    def _on_mode_change(self, old: Mode, new: Mode, reason: str) -> None:
        self.add_event("mode", **{"from": old.value, "to": new.value, "reason": reason})
        if new in (Mode.ESTOP,):
            self.add_event("estop", reason=reason)
        if new == Mode.FAULT:
            self.add_event("fault", reason=reason)


def _prioritize_this_thread(nice: int) -> int | None:
    """Ask for ``nice`` on the calling thread; return the value it has (None off Linux)."""
    if not hasattr(os, "setpriority"):
        return None
    tid = threading.get_native_id()
    try:
        os.setpriority(os.PRIO_PROCESS, tid, nice)
    except OSError as exc:  # unprivileged: a thread may only lower its own priority
        log.info("control loop keeps its priority (nice %d refused: %s)", nice, exc.strerror)
    return os.getpriority(os.PRIO_PROCESS, tid)


def _process_priority_for_this_thread() -> None:
    """Give the calling thread the process's nice value (threads inherit their creator's)."""
    if hasattr(os, "setpriority"):
        with contextlib.suppress(OSError):
            process_nice = os.getpriority(os.PRIO_PROCESS, os.getpid())  # the main thread's
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), process_nice)
