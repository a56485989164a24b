"""The mode machine: every allowed and every refused transition of the table."""

from __future__ import annotations

import itertools

import pytest

from app.modes import (
    LIDAR_MODES,
    RESET_ONLY,
    TRANSITIONS,
    USER_REQUESTABLE,
    Mode,
    ModeMachine,
    TransitionRefused,
    no_lidar_reason,
)


def machine_in(mode: Mode) -> ModeMachine:
    m = ModeMachine()
    m._mode = mode  # place the machine in a state directly; the table is what is under test
    return m


ALL_PAIRS = [(a, b) for a, b in itertools.product(Mode, Mode) if a != b]


@pytest.mark.parametrize(("src", "dst"), ALL_PAIRS, ids=[f"{a.value}->{b.value}" for a, b in ALL_PAIRS])
def test_operator_request_follows_table(src: Mode, dst: Mode) -> None:
    m = machine_in(src)
    allowed = dst in TRANSITIONS[src] and dst in USER_REQUESTABLE and (src, dst) not in RESET_ONLY
    if allowed:
        assert m.request(dst) == dst
        assert m.mode == dst
    else:
        with pytest.raises(TransitionRefused) as info:
            m.request(dst)
        assert m.mode == src
        assert info.value.current == src
        assert info.value.allowed == m.allowed()
        body = info.value.as_dict()
        assert body["mode"] == src.value and body["requested"] == dst.value and body["detail"]


@pytest.mark.parametrize(("src", "dst"), ALL_PAIRS, ids=[f"{a.value}->{b.value}" for a, b in ALL_PAIRS])
def test_system_enter_follows_table(src: Mode, dst: Mode) -> None:
    m = machine_in(src)
    ok = m.enter(dst, "test")
    assert ok == (dst in TRANSITIONS[src] and (src, dst) not in RESET_ONLY)
    assert m.mode == (dst if ok else src)


def test_estop_reachable_from_every_mode_and_latches() -> None:
    for src in Mode:
        m = machine_in(src)
        assert m.enter(Mode.ESTOP, "button") or src == Mode.ESTOP
        assert m.mode == Mode.ESTOP
        for target in USER_REQUESTABLE:
            with pytest.raises(TransitionRefused):
                m.request(target)
        assert m.reset() == Mode.IDLE


def test_reset_refused_when_fault_persists_and_outside_estop() -> None:
    m = machine_in(Mode.FAULT)
    with pytest.raises(TransitionRefused, match="link still lost"):
        m.reset(blocked_by="link still lost")
    assert m.mode == Mode.FAULT
    assert m.reset() == Mode.IDLE
    with pytest.raises(TransitionRefused, match="nothing to reset"):
        m.reset()


def test_unknown_and_system_only_modes_refused() -> None:
    m = ModeMachine()
    with pytest.raises(TransitionRefused, match="unknown mode"):
        m.request("flying")
    for target in (Mode.ESTOP, Mode.FAULT, Mode.RECOVERING):
        with pytest.raises(TransitionRefused, match="cannot be requested directly"):
            m.request(target)


def test_guard_refuses_with_reason_and_change_callback() -> None:
    seen = []
    m = ModeMachine(on_change=lambda a, b, r: seen.append((a, b, r)))
    m.set_guard(Mode.NAVIGATING, lambda: "not localized")
    with pytest.raises(TransitionRefused, match="not localized"):
        m.request("navigating")
    m.request("teleop")
    assert seen == [(Mode.IDLE, Mode.TELEOP, "operator request")]


def test_unavailable_modes_are_refused_with_their_reason_and_not_offered() -> None:
    """Issue 23 item 2: a robot without a lidar never enters a mode that needs scans."""
    m = ModeMachine()
    m.set_unavailable(LIDAR_MODES, no_lidar_reason("that mode"))
    assert set(m.allowed()) == {"teleop"}
    for mode in LIDAR_MODES:
        with pytest.raises(TransitionRefused) as exc:
            m.request(mode)
        assert str(exc.value).startswith("this robot has no lidar:") and m.mode == Mode.IDLE
        assert not m.enter(mode, "system")
    assert m.request(Mode.TELEOP) == Mode.TELEOP
    assert m.unavailable() == {mode.value: no_lidar_reason("that mode") for mode in LIDAR_MODES}
