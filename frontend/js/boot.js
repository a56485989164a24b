// Classic (non-module) script at the top of the Live page: runs while the page is still parsing, before
// the module graph and the 3D view's iframe load. Starts the WebGL warm-up worker (see gl-warmup.js).
(() => {
  const perf = (window.__navdeck = window.__navdeck || { firstFrameMs: null, keyDownAt: [], telemetryAt: null });
  if (typeof OffscreenCanvas === "undefined" || typeof Worker === "undefined") return;
  const w = new Worker("/js/gl-warmup.js");
  w.onmessage = (ev) => { perf.glWarmup = { ...ev.data, doneMs: performance.now() }; };
})();
