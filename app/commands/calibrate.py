"""``navdeck calibrate``: drive a straight line and in-place turns, ask what was measured, and write
the corrected ``wheel_radius`` and ``track_width`` (``omni_radius`` for omni bases) into a copy of
the profile TOML (math in ``robot.calibration``, procedure in docs/hardware.md).

The robot drives itself (the same ``Driver`` as ``serve``, so serial hardware and the simulator are
calibrated alike): ``--distance`` metres straight by its current odometry, then ``--turns`` turns in
place by its gyro (encoders without one). The operator measures what really happened with a tape
and a floor mark and types it in; ``--measured-distance`` / ``--measured-turns`` give the numbers
up front and ``--yes`` skips the confirmations, for automation. With ``--robot sim`` the simulator's
ground truth is offered as the measurement, and ``--sim-profile`` sets the simulated robot's true
geometry so a wrong ``--profile`` can be rehearsed.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from app.cli import CliError

if TYPE_CHECKING:
    from collections.abc import Callable

    import numpy as np

    from nav.types import Twist2D
    from robot.base import Driver
    from robot.clock import Clock
    from robot.profiles import RobotProfile


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="measure and correct wheel radius and track width")
    p.add_argument("--robot", default="sim", help="'sim' or serial:///dev/ttyUSB0?lidar=/dev/ttyUSB1")
    p.add_argument("--profile", default="skid4", help="profile to correct (stock name or TOML path)")
    p.add_argument(
        "--world", default="box", help="simulator only: box (empty room), a stock world or a map YAML"
    )
    p.add_argument("--sim-profile", help="simulator only: the simulated robot's true profile")
    p.add_argument("--seed", type=int, default=0, help="simulator random seed")
    p.add_argument("--distance", type=float, default=1.0, help="straight run length in metres (>= 0.2)")
    p.add_argument("--speed", type=float, default=0.1, help="straight run speed, m/s")
    p.add_argument("--turns", type=float, default=2.0, help="in-place turns to make (>= 0.5)")
    p.add_argument("--turn-speed", type=float, default=0.6, help="turn rate, rad/s")
    p.add_argument("--measured-distance", type=float, help="metres the robot really moved (skips the prompt)")
    p.add_argument("--measured-turns", type=float, help="turns the robot really made (skips the prompt)")
    p.add_argument("--gyro-turns", action="store_true", help="take the gyro's angle as the measured turns")
    p.add_argument(
        "--write",
        metavar="PATH",
        help="where to write the corrected profile (default <name>-calibrated.toml)",
    )
    p.add_argument(
        "--set-firmware",
        action="store_true",
        help="serial only: also PARAM_SET the new values, then PARAM_SAVE them to flash (asks before each)",
    )
    p.add_argument("--yes", "-y", action="store_true", help="no confirmations (automation)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from app.drivers import DriverConfigError, make_driver
    from robot.calibration import CalibrationError, calibrate, profile_name_for, update_profile_toml
    from robot.clock import RealClock, VirtualClock
    from robot.profiles import ProfileError, load_profile

    if args.distance < 0.2 or args.speed <= 0 or args.turns < 0.5 or args.turn_speed <= 0:
        raise CliError("need --distance >= 0.2, --turns >= 0.5 and positive --speed / --turn-speed")
    try:
        profile = load_profile(args.profile)
        true_profile = load_profile(args.sim_profile) if args.sim_profile else profile
    except ProfileError as exc:
        raise CliError(str(exc)) from None
    lim = profile.limits
    if args.speed > lim.max_vel_x or args.turn_speed > lim.max_vel_theta:
        raise CliError(
            f"--speed / --turn-speed above the profile's limits"
            f" ({lim.max_vel_x} m/s, {lim.max_vel_theta} rad/s)"
        )
    if not profile.source:
        raise CliError(f"profile {args.profile!r} has no TOML file to copy")
    is_sim = args.robot == "sim"
    if args.sim_profile and not is_sim:
        raise CliError("--sim-profile only applies to --robot sim")
    if args.set_firmware and is_sim:
        raise CliError("--set-firmware only applies to a serial:// robot")
    clock = VirtualClock() if is_sim else RealClock()  # the simulator needs no wall time
    try:
        if is_sim and args.world == "box":  # an empty 6 x 4 m room: nothing in the way of the runs
            from robot.sim import SimDriver, World

            world = World.box(6.0, 4.0)
            driver = SimDriver(world, true_profile, clock, seed=args.seed, start_pose=world.start_pose)
        else:
            driver = make_driver(args.robot, true_profile, args.world, clock, args.seed).driver
    except DriverConfigError as exc:
        raise CliError(str(exc)) from None
    ask = _Asker(args.yes)
    rig = _Rig(driver, profile, clock)
    try:
        rig.wait_for_telemetry()
        if rig.has_gyro:
            print(
                f"gyro bias: {rig.gyro_bias:+.5f} rad/s ({math.degrees(rig.gyro_bias):+.3f} deg/s),"
                " measured standing still; subtracted from the turn's gyro angle"
            )
        ask.enter(
            f"Put the robot on a start mark with {args.distance + 0.3:.1f} m clear ahead, then press Enter."
        )
        straight = rig.straight(args.distance, args.speed)
        print(f"straight run: encoders say {straight.encoder_distance:.4f} m")
        measured_d = args.measured_distance
        if measured_d is None:
            truth = rig.truth_distance(straight)
            measured_d = ask.number("Measured distance travelled (m)", truth)
        ask.enter(f"Mark the robot's heading; it will turn {args.turns:g} times in place. Press Enter.")
        turn = rig.spin(args.turns * 2 * math.pi, args.turn_speed)
        gyro_txt = f", gyro {turn.gyro_angle / (2 * math.pi):.3f}" if turn.gyro_angle is not None else ""
        print(f"turn run: encoders say {turn.encoder_angle / (2 * math.pi):.3f} turns{gyro_txt}")
        measured_angle: float | None
        if args.gyro_turns:
            measured_angle = None
        elif args.measured_turns is not None:
            measured_angle = args.measured_turns * 2 * math.pi
        else:
            truth = rig.truth_angle(turn)
            truth_turns = None if truth is None else truth / (2 * math.pi)
            measured_angle = 2 * math.pi * ask.number("Measured turns (fractions allowed)", truth_turns)
        result = calibrate(profile, straight.dticks, measured_d, turn.dticks, measured_angle, turn.gyro_angle)
        if args.set_firmware:
            _write_firmware(rig, result.changes(), ask)
    except CalibrationError as exc:
        raise CliError(str(exc)) from None
    finally:
        rig.close()
    for warning in result.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    print(f"wheel_radius: {result.wheel_radius:.5f} -> {result.wheel_radius_new:.5f} m")
    print(f"{result.turn_field}: {result.turn_value:.5f} -> {result.turn_value_new:.5f} m")
    out = Path(args.write) if args.write else Path.cwd() / f"{profile.name}-calibrated.toml"
    name = profile_name_for(out)
    if not args.yes and not ask.confirm(f"Write the corrected profile to {out} (name = {name!r})?"):
        print("not written")
        return 0
    changes: dict[str, float | str] = {**result.changes(), "name": name}
    text = update_profile_toml(Path(profile.source).read_text(), changes)
    try:
        out.write_text(text)
    except OSError as exc:
        raise CliError(f"cannot write {out}: {exc.strerror or exc}") from None
    print(f"wrote {out}")
    return 0


FIRMWARE_PERSISTENCE = (
    "PARAM_SET values live in the base's RAM: a reboot brings back the values last saved to flash"
    " (or the firmware defaults) unless they are saved with PARAM_SAVE"
)


def _write_firmware(rig: _Rig, values: dict[str, float], ask: _Asker) -> None:
    """PARAM_SET the corrected values, then PARAM_SAVE them to flash, each after the operator said
    yes (``--yes`` answers yes to both). Nothing reaches the base before the first yes."""
    listing = ", ".join(f"{k} = {v:.5f}" for k, v in values.items())
    print(f"note: {FIRMWARE_PERSISTENCE}")
    if not ask.yes and not ask.confirm(f"Write {listing} into the base's firmware parameters?"):
        print("firmware not changed")
        return
    rig.set_firmware(values)
    save = "Save them to the base's flash so they survive a reboot (PARAM_SAVE)?"
    if not ask.yes and not ask.confirm(save):
        print("not saved to flash: the base goes back to its saved values at the next reboot")
        return
    rig.save_firmware()


class _Asker:
    """Operator prompts on stdin; with no terminal (EOF) a missing answer is a one-line error."""

    def __init__(self, yes: bool) -> None:
        self.yes = yes

    def _input(self, prompt: str) -> str:
        try:
            return input(prompt)
        except EOFError:
            raise CliError(f"no answer to {prompt.strip()!r}: give it as a flag (see --help)") from None

    def enter(self, message: str) -> None:
        if not self.yes:
            self._input(message + " ")

    def confirm(self, message: str) -> bool:
        return self._input(message + " [y/N] ").strip().lower() in ("y", "yes")

    def number(self, label: str, default: float | None) -> float:
        if default is not None and self.yes:
            print(f"{label}: {default:.4f} (simulator ground truth)")
            return default
        hint = f" [simulator ground truth {default:.4f}]" if default is not None else ""
        while True:
            text = self._input(f"{label}{hint}: ").strip()
            if not text and default is not None:
                return default
            try:
                value = float(text)
            except ValueError:
                print(f"not a number: {text!r}")
                continue
            if math.isfinite(value) and value > 0:
                return value
            print("give a positive number")


def _bar(fraction: float, width: int = 20) -> str:
    """``[#######-------------]  35%``: a text progress bar for a terminal line."""
    f = min(max(fraction, 0.0), 1.0)
    n = round(f * width)
    return f"[{'#' * n}{'-' * (width - n)}] {f * 100:3.0f}%"


@dataclass(frozen=True)
class _Run:
    """One calibration run: encoder deltas, the gyro's integrated angle and ground truth if simulated."""

    dticks: np.ndarray
    encoder_distance: float  # m, with the profile being calibrated
    encoder_angle: float  # rad, idem
    gyro_angle: float | None  # rad, bias-corrected integral; None without a gyro
    truth: tuple[float, float] | None  # simulator: (distance, unwrapped yaw change)


class _Rig:
    """Drives the robot through a ``Driver`` at 20 Hz and integrates encoders and gyro."""

    PERIOD = 0.05
    PROGRESS_PERIOD = 0.5  # s between progress line updates on stderr

    def __init__(self, driver: Driver, profile: RobotProfile, clock: Clock) -> None:
        self.driver = driver
        self.profile = profile
        self.clock = clock
        self.ticks: np.ndarray | None = None  # latest cumulative encoder counts
        self.stamp: float | None = None
        self.gyro_bias = 0.0
        self.gyro_angle = 0.0  # unwrapped, bias-corrected integral since the start
        self.has_gyro = False
        self.truth_yaw = 0.0  # unwrapped ground truth (simulator only)
        self._truth_prev = getattr(driver, "truth_pose", None)
        self._still_gyro: list[float] = []

    def _tick(self, cmd: Twist2D | None) -> None:
        import numpy as np

        from nav.types import wrap_angle

        if cmd is None:
            self.driver.stop()
        else:
            self.driver.command(cmd)
        self.clock.sleep_until(self.clock.now() + self.PERIOD)
        frame = self.driver.read()
        if frame.fault:
            raise CliError(f"robot fault: {frame.fault}")
        if frame.ticks is not None:
            if self.stamp is not None and frame.imu is not None and math.isfinite(frame.imu.gyro_z):
                dt = frame.ticks.stamp - self.stamp
                self.has_gyro = True
                if 0 < dt < 1.0:
                    self.gyro_angle += (frame.imu.gyro_z - self.gyro_bias) * dt
                    moved = self.ticks is not None and bool(np.any(frame.ticks.counts != self.ticks))
                    if not moved and cmd is None:
                        self._still_gyro.append(frame.imu.gyro_z)
            self.ticks = frame.ticks.counts.copy()
            self.stamp = frame.ticks.stamp
        pose = getattr(self.driver, "truth_pose", None)
        if pose is not None and self._truth_prev is not None:
            self.truth_yaw += float(wrap_angle(pose.theta - self._truth_prev.theta))
            self._truth_prev = pose

    def wait_for_telemetry(self, timeout: float = 5.0) -> None:
        end = self.clock.now() + timeout
        while self.ticks is None and self.clock.now() < end:
            self._tick(None)
        if self.ticks is None:
            raise CliError(f"no encoder telemetry from the robot within {timeout:.0f} s")
        self._settle()

    def _settle(self, quiet: float = 0.4, timeout: float = 4.0) -> None:
        """Hold still until the encoders stop for ``quiet`` s; re-estimate the gyro bias meanwhile."""
        import numpy as np

        end = self.clock.now() + timeout
        self._still_gyro = []
        last, since = self.ticks, self.clock.now()
        while self.clock.now() < end:
            self._tick(None)
            if last is None or np.any(self.ticks != last):
                last, since, self._still_gyro = self.ticks, self.clock.now(), []
            elif self.clock.now() - since >= quiet:
                break
        if len(self._still_gyro) >= 3:
            self.gyro_bias = float(np.mean(self._still_gyro))

    def _run(
        self,
        cmd: Twist2D,
        done: Callable[[tuple[float, float], float], bool],
        timeout: float,
        progress: Callable[[tuple[float, float], float], str],
    ) -> _Run:
        from robot.calibration import encoder_motion

        t0, pose0, yaw0, gyro0 = self.ticks.copy(), self._truth_prev, self.truth_yaw, self.gyro_angle
        end = self.clock.now() + timeout
        shown = -math.inf
        while not done(motion := encoder_motion(self.profile, self.ticks - t0), self.gyro_angle - gyro0):
            if self.clock.now() - shown >= self.PROGRESS_PERIOD:  # one line rewritten in place
                shown = self.clock.now()
                print(f"\r{progress(motion, self.gyro_angle - gyro0)}", end="", file=sys.stderr, flush=True)
            if self.clock.now() > end:
                print(file=sys.stderr)
                self._settle()
                raise CliError(f"the run did not finish within {timeout:.0f} s (is the robot blocked?)")
            self._tick(cmd)
        print(f"\r{progress(motion, self.gyro_angle - gyro0)}", file=sys.stderr, flush=True)
        self._settle()
        dticks = self.ticks - t0
        dist, ang = encoder_motion(self.profile, dticks)
        truth = None
        if pose0 is not None and self._truth_prev is not None:
            truth = (self._truth_prev.distance_to(pose0), self.truth_yaw - yaw0)
        return _Run(dticks, dist, ang, (self.gyro_angle - gyro0) if self.has_gyro else None, truth)

    def straight(self, distance: float, speed: float) -> _Run:
        from nav.types import Twist2D

        def progress(enc: tuple[float, float], _gyro: float) -> str:
            return f"driving: {_bar(enc[0] / distance)} {enc[0]:.2f} / {distance:.2f} m"

        return self._run(
            Twist2D(speed, 0.0, 0.0), lambda enc, _g: enc[0] >= distance, 3 * distance / speed + 5, progress
        )

    def spin(self, angle: float, rate: float) -> _Run:
        from nav.types import Twist2D

        def done(enc: tuple[float, float], gyro: float) -> bool:
            return (gyro if self.has_gyro else enc[1]) >= angle

        def progress(enc: tuple[float, float], gyro: float) -> str:
            turned, goal = (gyro if self.has_gyro else enc[1]) / (2 * math.pi), angle / (2 * math.pi)
            by = "gyro" if self.has_gyro else "encoders"
            return f"turning: {_bar(turned / goal)} {turned:.2f} / {goal:.2f} turns ({by})"

        return self._run(Twist2D(0.0, 0.0, rate), done, 3 * angle / rate + 5, progress)

    @staticmethod
    def truth_distance(run: _Run) -> float | None:
        return run.truth[0] if run.truth else None

    @staticmethod
    def truth_angle(run: _Run) -> float | None:
        return run.truth[1] if run.truth else None

    def set_firmware(self, values: dict[str, float]) -> None:
        from robot.serial.protocol import ParamId

        ids = {"wheel_radius": ParamId.WHEEL_RADIUS, "track_width": ParamId.TRACK_WIDTH}
        ids["omni_radius"] = ParamId.OMNI_RADIUS
        for name, value in values.items():
            try:
                reply = self.driver.set_param(ids[name], value)
            except Exception as exc:  # a timeout or a refusal: the profile is still written
                raise CliError(f"firmware parameter {name}: {exc}") from None
            print(f"firmware {name} = {reply.value:.5f}")

    def save_firmware(self) -> None:
        try:
            reply = self.driver.save_params()
        except Exception as exc:  # no answer (older firmware) or a flash error: the profile is still written
            print(f"warning: firmware parameters not saved to flash: {exc}", file=sys.stderr)
            return
        print(f"saved {int(reply.value)} firmware parameters to flash: they now survive a reboot")

    def close(self) -> None:
        try:
            self.driver.stop()
        finally:
            self.driver.close()
