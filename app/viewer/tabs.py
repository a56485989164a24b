"""Per-browser-tab view state of the 3D view: which layers are ticked and what a click sets.

Only the robot is shared (issue 17 item 7): two operators looking at the same robot each keep their
own layer checkboxes and click mode. viser gives every websocket connection a ``ClientHandle`` with its
own GUI, but a page reload or a dropped connection is a new client. So the state lives here, keyed by
the *tab token* the page chose once (``client.py``'s boot script puts it in the websocket URL as
``?tab=``; the relay hands it to viser in the upstream URL), and a reconnecting tab finds its state again.

viser has no public per-client visibility for a shared node, so ``send_visibility`` queues viser's own
``SetSceneNodeVisibilityMessage`` (owner ``""``, the shared scope) on that one client's connection. The
shared nodes' visibility is then never broadcast after creation: viser sends a client's own buffer and
the broadcast buffer from two producers without a common order, so mixing both would race.
"""

from __future__ import annotations

import re
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qs, urlsplit

import viser
from viser import _messages

TAB_TOKEN = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
DEFAULT_TAB = ""
"""The tab of in-process callers (tests, the demo) and of REST calls that name none."""


@dataclass
class TabView:
    """One tab's view: ``kind`` is what a click sets ("goal" or "initial_pose"), ``layers`` maps a
    layer's scene node to whether its checkbox is ticked."""

    layers: dict[str, bool]
    kind: str = "goal"


@dataclass
class ClientView:
    """A connected viser client and the GUI elements built for it (in the shared folders)."""

    handle: Any
    tab: str
    click_mode: Any = None
    checks: dict[str, Any] = field(default_factory=dict)
    sent: dict[str, bool] = field(default_factory=dict)  # layer visibility last sent to this client


class TabRegistry:
    """Tab states by token (the most recent ``max_tabs`` kept) and the clients showing each."""

    def __init__(self, default_layers: dict[str, bool], max_tabs: int = 64) -> None:
        self._default_layers = dict(default_layers)
        self._max_tabs = max_tabs
        self._tabs: OrderedDict[str, TabView] = OrderedDict()
        self.clients: dict[int, ClientView] = {}
        self.lock = threading.RLock()

    def tab(self, token: str = DEFAULT_TAB) -> TabView:
        with self.lock:
            view = self._tabs.get(token)
            if view is None:
                view = self._tabs[token] = TabView(dict(self._default_layers))
                while len(self._tabs) > self._max_tabs:
                    self._tabs.popitem(last=False)
            self._tabs.move_to_end(token)
            return view

    def tab_of_client(self, client_id: int | None) -> str:
        with self.lock:
            c = None if client_id is None else self.clients.get(client_id)
            return DEFAULT_TAB if c is None else c.tab

    def clients_of(self, token: str) -> list[ClientView]:
        with self.lock:
            return [c for c in self.clients.values() if c.tab == token]


def valid_tab(token: str | None) -> str | None:
    """``token`` if it is a well-formed tab token, else None."""
    return token if token is not None and TAB_TOKEN.match(token) else None


def tab_of_connection(server: viser.ViserServer, client_id: int) -> str | None:
    """The tab token in the upstream URL of viser connection ``client_id`` (set by the relay), or None.

    viser keeps the raw connection (and its request line) only in its websocket server's private
    ``_live_connections``; without it (another viser) every client is its own tab."""
    conns = getattr(getattr(server, "_websock_server", None), "_live_connections", None)
    conn = None if conns is None else conns.get(client_id)
    path = getattr(getattr(conn, "request", None), "path", None)
    if not isinstance(path, str):
        return None
    return valid_tab(parse_qs(urlsplit(path).query).get("tab", [None])[0])


def send_visibility(client: Any, node: str, visible: bool) -> None:
    """Show or hide the shared scene node ``node`` for this one client only."""
    client._websock_connection.queue_message(_messages.SetSceneNodeVisibilityMessage(node, visible))
