"""Calibration: the pure math on closed-form runs, the TOML update, and ``navdeck calibrate`` against
the simulator and against the emulated STM32 base over a pseudo-terminal with a deliberately wrong
profile (the command must recover the true wheel radius and track width within 2 %)."""

from __future__ import annotations

import math
import threading
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from patience import patient_url

from app.cli import main
from nav.types import wrap_angle
from robot.calibration import (
    CalibrationError,
    calibrate,
    corrected_turn_geometry,
    corrected_wheel_radius,
    encoder_motion,
    update_profile_toml,
)
from robot.profiles import PROFILE_DIR, load_profile, profile_from_dict
from robot.serial.emulate import EmulatorPair
from robot.serial.port import open_port
from robot.serial.protocol import ParamId, ParamSave, ParamSet

TRUE = load_profile("skid4")
OMNI = load_profile("omni4")


def ticks_for(profile, left: float, right: float) -> np.ndarray:
    """Encoder deltas (FL, RL, FR, RR) of a robot with ``profile``'s true geometry whose virtual
    left/right wheels rolled ``left`` / ``right`` metres (floored like real counters)."""
    per_m = profile.ticks_per_rev / (2 * math.pi * profile.wheel_radius)
    return np.floor(np.array([left, left, right, right]) * per_m).astype(np.int64)


def wrong_toml(tmp_path: Path, radius: float = 0.0300, track: float = 0.23) -> Path:
    text = (PROFILE_DIR / "skid4.toml").read_text()
    path = tmp_path / "wrong.toml"
    path.write_text(update_profile_toml(text, {"wheel_radius": radius, "track_width": track}))
    return path


# ------------------------------------------------------------------------------------------ pure math
@settings(max_examples=60, deadline=None)
@given(
    r_err=st.floats(0.8, 1.2),
    t_err=st.floats(0.75, 1.3),
    distance=st.floats(0.5, 3.0),
    turns=st.floats(1.0, 5.0),
)
def test_closed_form_runs_recover_true_geometry(
    r_err: float, t_err: float, distance: float, turns: float
) -> None:
    wrong = profile_from_dict(
        {**_skid4_dict(), "wheel_radius": TRUE.wheel_radius * r_err, "track_width": TRUE.track_width * t_err}
    )
    straight = ticks_for(TRUE, distance, distance)
    phi = turns * 2 * math.pi
    arc = phi * TRUE.track_width / 2
    turn = ticks_for(TRUE, -arc, arc)
    res = calibrate(wrong, straight, distance, turn, phi)
    assert res.wheel_radius_new == pytest.approx(TRUE.wheel_radius, rel=2e-3)
    assert res.turn_field == "track_width"
    assert res.turn_value_new == pytest.approx(TRUE.track_width, rel=2e-3)
    assert res.warnings == ()
    # the uncorrected encoders were off by exactly the radius error
    assert res.encoder_distance == pytest.approx(distance * r_err, rel=2e-3)


def test_gyro_angle_can_stand_in_and_disagreement_warns() -> None:
    straight = ticks_for(TRUE, 1.0, 1.0)
    arc = 4 * math.pi * TRUE.track_width / 2
    turn = ticks_for(TRUE, -arc, arc)
    res = calibrate(TRUE, straight, 1.0, turn, None, gyro_angle=4 * math.pi)
    assert res.turn_value_new == pytest.approx(TRUE.track_width, rel=2e-3)
    res = calibrate(TRUE, straight, 1.0, turn, 3 * math.pi, gyro_angle=4 * math.pi)  # miscounted
    assert res.warnings and "recount" in res.warnings[0]
    with pytest.raises(CalibrationError):
        calibrate(TRUE, straight, 1.0, turn, None, gyro_angle=None)


def test_omni_turn_calibrates_omni_radius() -> None:
    phi = 2 * 2 * math.pi
    rim = phi * OMNI.omni_radius * 1.1  # the true radius is 10 % larger than the profile's
    per_m = OMNI.ticks_per_rev / (2 * math.pi * OMNI.wheel_radius)
    turn = np.round(np.full(4, rim) * per_m).astype(np.int64)
    name, value = corrected_turn_geometry(OMNI, turn, phi)
    assert name == "omni_radius" and value == pytest.approx(OMNI.omni_radius * 1.1, rel=1e-3)
    # a sideways straight run: front +, rear - (vy), distance from |(vx, vy)|
    d = 1.0
    side = np.round(np.array([d, 0.0, -d, 0.0]) * per_m).astype(np.int64)
    dist, yaw = encoder_motion(OMNI, side)
    assert dist == pytest.approx(d, rel=1e-3) and abs(yaw) < 1e-3
    assert corrected_wheel_radius(OMNI, side, 1.05) == pytest.approx(OMNI.wheel_radius * 1.05, rel=1e-3)


@pytest.mark.parametrize(
    ("straight", "measured", "message"),
    [
        ((1.0, 1.0), 0.05, "at least"),  # too short to be meaningful
        ((0.0, 0.0), 1.0, "did the wheels turn"),
        ((0.6, 1.4), 1.0, "not straight"),
        ((1.0, 1.0), 2.5, "check the measurement"),  # cm typed as dm, or the like
        ((1.0, 1.0), float("nan"), "measured distance"),
    ],
)
def test_implausible_runs_are_refused(straight: tuple[float, float], measured: float, message: str) -> None:
    with pytest.raises(CalibrationError, match=message):
        corrected_wheel_radius(TRUE, ticks_for(TRUE, *straight), measured)


def test_turn_in_the_wrong_direction_is_refused() -> None:
    arc = 2 * math.pi * TRUE.track_width / 2
    with pytest.raises(CalibrationError, match="other way"):
        corrected_turn_geometry(TRUE, ticks_for(TRUE, arc, -arc), 2 * math.pi)
    with pytest.raises(CalibrationError, match="at least"):
        corrected_turn_geometry(TRUE, ticks_for(TRUE, -arc, arc), 0.5)


# ------------------------------------------------------------------------------------------ TOML copy
def test_update_profile_toml_keeps_everything_else() -> None:
    text = (PROFILE_DIR / "skid4.toml").read_text()
    out = update_profile_toml(text, {"wheel_radius": 0.031234567, "track_width": 0.2012345})
    before, after = tomllib.loads(text), tomllib.loads(out)
    assert after["wheel_radius"] == 0.031235 and after["track_width"] == 0.20123
    del before["wheel_radius"], before["track_width"], after["wheel_radius"], after["track_width"]
    assert after == before  # every other field and table untouched
    changed = [(a, b) for a, b in zip(text.splitlines(), out.splitlines(), strict=True) if a != b]
    assert len(changed) == 2
    assert all(b.split("#")[1] == a.split("#")[1] for a, b in changed)  # comments kept
    assert "[lidar]" not in out.split("wheel_radius")[0]  # still top-level keys


def test_update_profile_toml_adds_missing_keys_before_the_first_table() -> None:
    out = update_profile_toml('name = "x"\n\n[limits]\nmax_vel_x = 0.3\n', {"track_width": 0.2})
    data = tomllib.loads(out)
    assert data["track_width"] == 0.2 and data["limits"] == {"max_vel_x": 0.3}
    assert "track_width" not in data["limits"]


# ------------------------------------------------------------------------------------------ the command
def test_calibrate_against_the_simulator_recovers_the_true_profile(tmp_path: Path, capsys) -> None:
    """Simulated robot with the true skid4 geometry, profile 8 % / 21 % wrong; ground truth measures."""
    out = tmp_path / "cal.toml"
    argv = ["calibrate", "--robot", "sim", "--profile", str(wrong_toml(tmp_path)), "--sim-profile", "skid4"]
    argv += ["--distance", "0.6", "--speed", "0.2", "--turns", "1", "--turn-speed", "0.8"]
    assert main([*argv, "--yes", "--write", str(out)]) == 0
    cal = load_profile(out)
    assert cal.wheel_radius == pytest.approx(TRUE.wheel_radius, rel=0.02)
    assert cal.track_width == pytest.approx(TRUE.track_width, rel=0.02)
    assert cal.limits == TRUE.limits and cal.ir == TRUE.ir  # the rest of the file is kept
    assert "simulator ground truth" in capsys.readouterr().out


def test_calibrate_flags_skip_the_prompts(tmp_path: Path, capsys, monkeypatch) -> None:
    """Measurements given up front: no prompt is shown; the written radius is r * measured / encoders."""

    def no_prompt(prompt: str = "") -> str:
        raise AssertionError(f"prompted: {prompt}")

    monkeypatch.setattr("builtins.input", no_prompt)
    out = tmp_path / "cal.toml"
    argv = ["calibrate", "--robot", "sim", "--distance", "0.4", "--speed", "0.2", "--turns", "0.75"]
    argv += ["--turn-speed", "0.8", "--measured-distance", "0.42", "--measured-turns", "0.75"]
    assert main([*argv, "--yes", "--write", str(out)]) == 0
    text = capsys.readouterr().out
    enc = float(text.split("encoders say ")[1].split(" m")[0])
    assert load_profile(out).wheel_radius == pytest.approx(TRUE.wheel_radius * 0.42 / enc, rel=1e-3)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--distance", "0.05"], "--distance"),
        (["--speed", "0.5"], "limits"),
        (["--profile", "nope"], "unknown profile"),
        (["--robot", "serial:///dev/nonexistent"], "not found"),
        (["--robot", "serial:///dev/nonexistent", "--sim-profile", "skid4"], "--sim-profile"),
    ],
)
def test_calibrate_user_errors_are_one_line(argv: list[str], message: str, capsys) -> None:
    assert main(["calibrate", *argv, "--yes"]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err


def test_calibrate_without_a_terminal_asks_for_the_flag(tmp_path: Path, monkeypatch, capsys) -> None:
    """A serial robot has no ground truth: with no stdin the missing measurement is a one-line error."""

    def eof(prompt: str = "") -> str:
        raise EOFError

    monkeypatch.setattr("builtins.input", eof)
    with EmulatorPair(TRUE, world="box", link_dir=tmp_path / "dev", lidar=False) as pair:
        argv = ["calibrate", "--robot", pair.url(), "--distance", "0.2", "--speed", "0.25", "--yes"]
        assert main(argv) == 2
    assert "give it as a flag" in capsys.readouterr().err


class TruthTape:
    """The operator's tape measure and floor mark: reads the emulated robot's ground truth and
    unwraps its heading on a 200 Hz sampler (the test's stand-in for a person watching)."""

    def __init__(self, pair: EmulatorPair) -> None:
        self.pump = pair.pump
        self.start = self.pump.truth_pose
        self.yaw = 0.0
        self._prev = self.start.theta
        self._yaw_mark = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()

    def _sample(self) -> None:
        while not self._stop.wait(0.005):
            th = self.pump.truth_pose.theta
            self.yaw += float(wrap_angle(th - self._prev))
            self._prev = th

    def answer(self, prompt: str = "") -> str:
        if "distance" in prompt:
            self._yaw_mark = self.yaw  # the turn run starts after the distance was measured
            return f"{self.pump.truth_pose.distance_to(self.start):.4f}"
        if "turns" in prompt:
            return f"{(self.yaw - self._yaw_mark) / (2 * math.pi):.4f}"
        raise AssertionError(f"unexpected prompt {prompt!r}")

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1.0)


def test_calibrate_over_serial_recovers_a_wrong_wheel_radius(tmp_path: Path, monkeypatch, capsys) -> None:
    """The full hardware path: SerialDriver <-> pty <-> emulated STM32 (true skid4 geometry in the
    firmware and the physics) while the host profile says 30.0 mm wheels and a 0.23 m track."""
    with EmulatorPair(TRUE, world="box", link_dir=tmp_path / "dev", lidar=False, seed=2) as pair:
        tape = TruthTape(pair)
        monkeypatch.setattr("builtins.input", tape.answer)
        out = tmp_path / "cal.toml"
        url = patient_url(pair)  # a starved emulator is not what is calibrated here
        argv = ["calibrate", "--robot", url, "--profile", str(wrong_toml(tmp_path))]
        argv += ["--distance", "0.5", "--speed", "0.25", "--turns", "0.6", "--turn-speed", "1.0"]
        try:
            rc = main([*argv, "--yes", "--write", str(out), "--set-firmware"])
        finally:
            tape.close()
        printed = capsys.readouterr()
        assert rc == 0, printed.err
        cal = load_profile(out)
        assert cal.wheel_radius == pytest.approx(TRUE.wheel_radius, rel=0.02)
        assert cal.track_width == pytest.approx(TRUE.track_width, rel=0.02)
        assert "gyro" in printed.out  # the turn was measured by the gyro too
        # --set-firmware wrote the corrected values into the base's parameters
        assert pair.base.params[1] == pytest.approx(cal.wheel_radius, rel=1e-4)
        assert pair.base.params[2] == pytest.approx(cal.track_width, rel=1e-4)
        # ... and, --yes answering the second question too, saved them to flash (PARAM_SAVE)
        assert pair.base.flash is not None
        assert pair.base.flash[1] == pytest.approx(cal.wheel_radius, rel=1e-4)
        assert "now survive a reboot" in printed.out


@pytest.mark.parametrize("answers", [("n", None), ("y", "n"), ("y", "y")])
def test_set_firmware_asks_before_any_write_and_before_saving_to_flash(
    tmp_path: Path, monkeypatch, capsys, answers: tuple[str, str | None]
) -> None:
    """Issue 23 item 3: without --yes, nothing reaches the base before the operator says yes to the
    firmware question; the note says PARAM_SET values do not survive a reboot unless saved; a second
    question offers PARAM_SAVE, and only a yes writes the flash."""
    write, save = answers
    with EmulatorPair(TRUE, world="box", link_dir=tmp_path / "dev", lidar=False, seed=2) as pair:
        prompts: list[str] = []

        def operator(prompt: str = "") -> str:
            prompts.append(prompt)
            if prompt.startswith("Write the corrected profile"):
                return "y"
            if "firmware parameters" in prompt:
                assert not [m for _, m in pair.base.message_log if isinstance(m, ParamSet | ParamSave)]
                return write
            if "(PARAM_SAVE)" in prompt:
                assert save is not None, "asked to save what was not written"
                assert not [m for _, m in pair.base.message_log if isinstance(m, ParamSave)]
                return save
            if prompt.startswith("Measured"):
                return tape.answer(prompt)
            return ""  # Enter at the "put the robot on a mark" prompts

        tape = TruthTape(pair)
        monkeypatch.setattr("builtins.input", operator)
        out = tmp_path / "wheelie.toml"
        url = patient_url(pair)
        before = dict(pair.base.params)
        argv = ["calibrate", "--robot", url, "--profile", str(wrong_toml(tmp_path))]
        argv += ["--distance", "0.5", "--speed", "0.25", "--turns", "0.6", "--turn-speed", "1.0"]
        argv += ["--write", str(out), "--set-firmware"]
        try:
            rc = main(argv)
        finally:
            tape.close()
        printed = capsys.readouterr()
        assert rc == 0, printed.err
        assert any("firmware parameters" in p for p in prompts), prompts
        assert any("Write the corrected profile" in p for p in prompts), (prompts, printed.out)
        assert "unless they are saved with PARAM_SAVE" in printed.out
        sent = [m for _, m in pair.base.message_log]
        if write == "n":
            assert not [m for m in sent if isinstance(m, ParamSet | ParamSave)]
            assert pair.base.params == before and "firmware not changed" in printed.out
        else:
            assert pair.base.params[ParamId.WHEEL_RADIUS] != before[ParamId.WHEEL_RADIUS]
        if save == "y":
            assert pair.base.flash == pair.base.params and "now survive a reboot" in printed.out
        else:
            assert pair.base.flash is None and not [m for m in sent if isinstance(m, ParamSave)]
        assert load_profile(out).name == "wheelie"  # the written profile is no longer "skid4"


def test_calibrate_prints_the_gyro_bias_and_progress(tmp_path: Path, capsys) -> None:
    """Issue 23 item 6: the measured gyro bias on stdout, a progress line on stderr for each run, and
    the written profile named after its file."""
    out = tmp_path / "my-robot.toml"
    argv = ["calibrate", "--robot", "sim", "--distance", "0.4", "--speed", "0.2", "--turns", "1"]
    argv += ["--turn-speed", "0.8", "--yes", "--write", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr()
    bias = printed.out.split("gyro bias: ")[1]
    assert "rad/s" in bias.splitlines()[0]
    float(bias.split(" rad/s")[0])  # a number
    assert "driving: [" in printed.err and "0.40 m" in printed.err
    assert "turning: [" in printed.err and "/ 1.00 turns (gyro)" in printed.err and "100%" in printed.err
    assert load_profile(out).name == "my-robot"
    assert 'name = "my-robot"' in out.read_text()


def _skid4_dict() -> dict:
    return tomllib.loads((PROFILE_DIR / "skid4.toml").read_text())


def test_calibrate_on_a_port_the_server_holds_says_to_stop_it(tmp_path: Path, capsys) -> None:
    """Issue 23 item 6: "port is busy" says what to do (stop the server first)."""
    with EmulatorPair(TRUE, world="box", link_dir=tmp_path / "dev", lidar=False) as pair:
        held = open_port(pair.base_path, 115200)  # what a running `navdeck serve` does
        try:
            assert main(["calibrate", "--robot", pair.url(), "--yes"]) == 2
        finally:
            held.close()
    err = capsys.readouterr().err.strip()
    assert "is busy" in err and "stop a running `navdeck serve`" in err and "\n" not in err
