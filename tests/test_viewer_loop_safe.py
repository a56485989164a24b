"""viser's message buffers can be pushed into from our threads without corrupting their event."""

from __future__ import annotations

import asyncio
import threading

from viser.infra._async_message_buffer import AsyncMessageBuffer

from app.viewer import loop_safe


def _loop_in_thread() -> tuple[asyncio.AbstractEventLoop, threading.Thread]:
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    return loop, thread


def test_a_set_from_another_thread_never_touches_the_waiters_there() -> None:
    """The waiter is resolved by the buffer's own loop, never by the pushing thread (the race that
    froze every tab: a foreign set() iterating waiters while the loop adds one)."""
    loop_safe.install()
    loop, thread = _loop_in_thread()
    try:
        buffer = AsyncMessageBuffer(loop, persistent_messages=True)
        assert isinstance(buffer.message_event, loop_safe.LoopSafeEvent)
        waiter = asyncio.run_coroutine_threadsafe(buffer.message_event.wait(), loop)
        started = threading.Event()
        release = threading.Event()
        while not buffer.message_event._waiters:  # the wait() is parked on its future
            threading.Event().wait(0.01)

        def hold_the_loop() -> None:
            started.set()
            release.wait(10.0)

        loop.call_soon_threadsafe(hold_the_loop)
        assert started.wait(10.0)
        buffer.message_event.set()  # from this thread, while the loop is busy
        parked = list(buffer.message_event._waiters)
        assert parked and not any(f.done() for f in parked)  # untouched here
        release.set()
        assert waiter.result(timeout=10.0) is True  # and woken by the loop itself
    finally:
        loop.call_soon_threadsafe(loop.stop)
        thread.join(10.0)
        loop.close()


def test_install_is_idempotent_and_a_closed_loop_is_tolerated() -> None:
    loop_safe.install()
    first = AsyncMessageBuffer.__init__
    loop_safe.install()
    assert AsyncMessageBuffer.__init__ is first
    loop = asyncio.new_event_loop()
    buffer = AsyncMessageBuffer(loop, persistent_messages=False)
    loop.close()
    buffer.message_event.set()  # nothing left to wake; no error
