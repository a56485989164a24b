// Worker: create one WebGL2 context off the main thread as soon as the Live page starts loading.
//
// A browser's first WebGL context is the expensive one (the GPU process brings up its GL/Vulkan
// backend: 1.5-2.5 s under SwiftShader, tens of ms on a real GPU; later contexts cost ~15 ms). Doing it
// here overlaps that set-up with the 3D view's download and script compile, instead of blocking the
// view's main thread when three.js asks for its context. The attributes match viser's renderer.
const t0 = performance.now();
let ok = false;
try {
  const gl = new OffscreenCanvas(16, 16).getContext("webgl2", {
    alpha: true, depth: true, stencil: false, antialias: true, premultipliedAlpha: true,
    preserveDrawingBuffer: true, powerPreference: "high-performance",
  });
  if (gl) {
    gl.clearColor(0, 0, 0, 1);
    gl.clear(gl.COLOR_BUFFER_BIT);
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4)); // waits for the GPU side
    ok = true;
  }
} catch { /* no OffscreenCanvas WebGL: the view pays the set-up itself */ }
postMessage({ ok, ms: performance.now() - t0 });
close();
