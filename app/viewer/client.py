"""viser's browser client, unpacked once per process and served as separate, cacheable files.

viser ships its client as a single ``index.html`` (818 KB). That page holds a base-88 text blob with the
zstd-compressed JS bundle (2.5 MB) and CSS, plus a gzipped zstd decoder in WebAssembly. In the browser
it decodes all of it, publishes the decoder as ``globalThis.__viserZstdWasm`` (the app decodes scene
messages with it), and injects the bundle as an *inline* module script. An inline script is parsed and
compiled on the page's main thread, only after that decode, and its compiled code is never cached.

Here the same bytes are unpacked in Python (viser already depends on ``zstandard``), so ``/viz/`` is a
small page that references them as files. The browser requests the bundle while parsing that page,
compiles it off the main thread (streaming compilation), and keeps the compiled code in its cache for
the next visit. The client code is byte-for-byte viser's, and only the loader changes. If the page
ever has another layout (a new viser version), ``unpack`` returns None and the original page is
served.
"""

from __future__ import annotations

import functools
import gzip
import hashlib
import logging
import pathlib
import re
from dataclasses import dataclass

import numpy as np
import viser
import zstandard

log = logging.getLogger(__name__)

CLIENT_HTML = pathlib.Path(viser.__file__).parent / "client" / "build" / "index.html"

# viser's base-88 alphabet (the loader's ``A``): 5 characters carry 4 bytes, big-endian.
_ALPHABET = "!#$%()*+,-./0123456789:;=?@ABCDEFGHIJKLMNOPQRSTUVWXYZ[\\]^_abcdefghijklmnopqrstuvwxyz{|}~"
_LOADER = re.compile(r'<script data-p="([^"]*)" data-ss="(\d+)" data-cs="(\d+)">(.*?)</script>', re.S)
_WASM = re.compile(r'const gzWasm="((?:[^"\\]|\\.)*)"')


# Runs before the client: the page picks a random token for this browser tab (kept across reconnects,
# since the page stays) and connects to ``/viz?tab=<token>`` through viser's own ``?websocket=`` option.
# The relay hands the token to viser so the server keeps this tab's layers and click mode (tabs.py); the
# dashboard reads ``__navdeckTab`` from its iframe to address the same view. Replays (``playbackPath``)
# have no websocket.
TAB_SCRIPT = """// navdeck: this tab's view token (per-tab layers and click mode).
{
  const q = new URLSearchParams(location.search);
  const given = /[?&]tab=([A-Za-z0-9_-]+)/.exec(q.get("websocket") || "");
  if (given) globalThis.__navdeckTab = given[1]; // a reload of a page that has its token already
  else if (!q.has("websocket") && !q.has("playbackPath")) {
    const bytes = crypto.getRandomValues(new Uint8Array(12));
    const tab = Array.from(bytes, (b) => b.toString(16).padStart(2, "0")).join("");
    globalThis.__navdeckTab = tab;
    const base = location.href.split("?")[0].replace(/\\/$/, "").replace(/^http/, "ws");
    q.set("websocket", `${base}?tab=${tab}`);
    history.replaceState(history.state, "", `?${q}`);
  }
}
"""


@dataclass(frozen=True)
class Asset:
    body: bytes
    media_type: str


@dataclass(frozen=True)
class ClientFiles:
    """The ``/viz/`` page and the files it references (``assets/<name>``, names carry a content hash)."""

    page: bytes
    assets: dict[str, Asset]


def _decode88(text: str) -> bytes:
    """viser's loader ``de()``, vectorized: groups of 5 digits -> 4 bytes; a last group of r digits
    -> r - 1 bytes."""
    lut = np.zeros(128, np.uint64)
    lut[np.frombuffer(_ALPHABET.encode(), np.uint8)] = np.arange(len(_ALPHABET), dtype=np.uint64)
    digits = lut[np.frombuffer(text.encode("ascii"), np.uint8)]
    n, r = divmod(len(digits), 5)
    weights = np.uint64(88) ** np.arange(4, -1, -1, dtype=np.uint64)
    whole = (digits[: n * 5].reshape(n, 5) * weights).sum(axis=1).astype(">u4").tobytes()
    if not r:
        return whole
    v = 0
    for d in digits[n * 5 :]:
        v = v * 88 + int(d)
    return whole + v.to_bytes(r - 1, "big")


def _name(stem: str, body: bytes, ext: str) -> str:
    return f"{stem}-{hashlib.sha256(body).hexdigest()[:12]}.{ext}"


def unpack(html: str) -> ClientFiles | None:
    """Split viser's single-file page into a light page plus CSS, JS and the zstd decoder, or None
    when the page does not have the layout this code knows."""
    m = _LOADER.search(html)
    w = _WASM.search(html)
    if m is None or w is None:
        return None
    css_len, js_len = int(m.group(2)), int(m.group(3))
    packed = _decode88(m.group(1))
    bundle = zstandard.ZstdDecompressor().decompress(packed, max_output_size=css_len + js_len)
    if len(bundle) != css_len + js_len:
        return None
    # the JS string literal escapes only backslashes (the alphabet has no quote)
    wasm = gzip.decompress(_decode88(w.group(1).replace("\\\\", "\\")))
    if not wasm.startswith(b"\0asm"):
        return None
    css, js = bundle[:css_len], bundle[css_len:]
    names = {
        "css": _name("viser", css, "css"),
        "js": _name("viser", js, "js"),
        "wasm": _name("zstd", wasm, "wasm"),
    }
    # The bundle reads __viserZstdWasm when it starts: publish it first, then run the bundle (which the
    # page has already been fetching and compiling since its modulepreload).
    boot = (
        f"{TAB_SCRIPT}"
        "// Publish viser's zstd decoder as its single-file loader does, then start the client.\n"
        f'const url = new URL("{names["wasm"]}", import.meta.url);\n'
        "globalThis.__viserZstdWasm = await WebAssembly.compileStreaming(fetch(url));\n"
        f'await import("./{names["js"]}");\n'
    ).encode()
    names["boot"] = _name("boot", boot, "js")
    head = (
        '<link rel="icon" href="/favicon.svg" type="image/svg+xml">\n'
        f'<link rel="modulepreload" href="assets/{names["js"]}">\n'
        f'<link rel="preload" href="assets/{names["wasm"]}" as="fetch" crossorigin>\n'
        f'<link rel="stylesheet" href="assets/{names["css"]}">\n'
        f'<script type="module" src="assets/{names["boot"]}"></script>'
    )
    page = html[: m.start()] + head + html[m.end() :]
    return ClientFiles(
        page=page.encode(),
        assets={
            names["css"]: Asset(css, "text/css; charset=utf-8"),
            names["js"]: Asset(js, "text/javascript; charset=utf-8"),
            names["wasm"]: Asset(wasm, "application/wasm"),
            names["boot"]: Asset(boot, "text/javascript; charset=utf-8"),
        },
    )


@functools.cache
def client_files() -> ClientFiles | None:
    """The unpacked client of the installed viser (computed once; about 50 ms), or None to serve
    viser's own page."""
    try:
        files = unpack(CLIENT_HTML.read_text(encoding="utf-8"))
    except (OSError, ValueError, zstandard.ZstdError) as exc:
        log.warning("viser client not unpacked (serving its single-file page): %s", exc)
        return None
    if files is None:
        log.warning("viser client page has an unknown layout: serving it as it is")
    return files
