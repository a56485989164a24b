"""Make viser's message buffers safe to push into from our threads.

viser 1.1.1's ``AsyncMessageBuffer.push`` calls ``asyncio.Event.set()`` on its ``message_event``
directly in the calling thread (our scene and grid threads, viser's own callback pool) before it
also schedules the set with ``call_soon_threadsafe``. ``asyncio.Event`` is not thread-safe: the
foreign ``set()`` iterates the waiters while the loop thread adds or removes one, raising "deque
mutated during iteration" after the flag is already true and before the thread-safe wake-up. The
senders then sleep on futures nobody resolves, with the flag set so no later push wakes them: every
open tab froze and new tabs never connected (seen in CI under load).

``install()`` gives every buffer an event whose ``set()`` from any thread other than the buffer's
loop is handed to that loop, which is what ``call_soon_threadsafe`` after it already does. The
synchronous set viser makes "to read the value immediately" is not relied on anywhere in viser
1.1.1 (the event is only read by the loop's ``wait()``/``clear()``).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
from typing import Any

from viser.infra._async_message_buffer import AsyncMessageBuffer


class LoopSafeEvent(asyncio.Event):
    """An ``asyncio.Event`` bound to ``loop`` whose ``set()`` from another thread runs on ``loop``."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__()
        self._owner = loop

    def set(self) -> None:
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._owner:
            super().set()
            return
        with contextlib.suppress(RuntimeError):  # a closed loop has nobody left to wake
            self._owner.call_soon_threadsafe(super().set)


def install() -> None:
    """Patch ``AsyncMessageBuffer`` so each new buffer uses a ``LoopSafeEvent`` (idempotent)."""
    if getattr(AsyncMessageBuffer.__init__, "_navdeck_loop_safe", False):
        return
    original = AsyncMessageBuffer.__init__

    @functools.wraps(original)
    def init(self: AsyncMessageBuffer, *args: Any, **kwargs: Any) -> None:
        original(self, *args, **kwargs)
        if not isinstance(self.message_event, LoopSafeEvent):
            self.message_event = LoopSafeEvent(self.event_loop)

    init._navdeck_loop_safe = True  # type: ignore[attr-defined]
    AsyncMessageBuffer.__init__ = init  # type: ignore[method-assign]
