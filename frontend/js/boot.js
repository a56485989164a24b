// Classic (non-module, async) script at the top of the Live page: runs as soon as it arrives, while the
// page is still parsing and before the module graph loads; the parser does not wait for it, so the 3D
// view's iframe starts loading at once. Starts the WebGL warm-up worker (see gl-warmup.js).
(() => {
  const perf = (window.__navdeck = window.__navdeck || { firstFrameMs: null, keyDownAt: [], telemetryAt: null });
  if (typeof OffscreenCanvas === "undefined" || typeof Worker === "undefined") return;
  const w = new Worker("/js/gl-warmup.js");
  w.onmessage = (ev) => { perf.glWarmup = { ...ev.data, doneMs: performance.now() }; };
})();
