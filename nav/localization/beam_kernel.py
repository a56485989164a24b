"""The beam model's measurement update as one compiled pass over particles x beams.

``sensor_models.beam_model_weights`` is the numpy reference: it ray-casts every (particle, beam)
into an (N, B) array of expected ranges, then scores the mixture with (N, B) temporaries. Here
each ray is cast (``sphere_trace.trace_ray``: jumps across open space by an uncapped clearance
table, an exact cell walk near obstacles), scored and summed into its particle's ``sum p^3`` at
once: no temporaries, and no separate passes over 120,000 rays per update (2000 particles x 60
beams). Tests check it against the reference.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from nav.localization.options import AmclOptions
from nav.localization.sphere_trace import ClearanceTracer, trace_fan


@njit(cache=True, nogil=True)
def _beam_log_weights(
    clear: np.ndarray,
    stride: int,
    width: int,
    height: int,
    u0: np.ndarray,
    v0: np.ndarray,
    heading: np.ndarray,
    bearings: np.ndarray,
    ranges: np.ndarray,
    range_max: float,
    resolution: float,
    mixture: np.ndarray,
) -> np.ndarray:
    """Per particle ``log(1 + sum_k p_k^3)``; origins (u0, v0) in grid-local cells, ``heading``
    in the grid's frame; ``mixture`` = (z_hit, z_short, z_max, z_rand, sigma_hit, lambda_short)."""
    z_hit, z_short, z_max, z_rand, sigma, lam = (
        mixture[0],
        mixture[1],
        mixture[2],
        mixture[3],
        mixture[4],
        mixture[5],
    )
    inv_two_var = 1.0 / (2.0 * sigma * sigma)
    t_max = range_max / resolution
    b = bearings.shape[0]
    # per beam: the parts of the mixture that depend on the reading only
    short = np.empty(b)
    floor_p = np.empty(b)
    for k in range(b):
        short[k] = z_short * lam * math.exp(-lam * ranges[k])
        floor_p[k] = z_max if ranges[k] >= range_max else z_rand / range_max
    cb, sb = np.cos(bearings), np.sin(bearings)
    # per-particle work arrays, allocated once per call
    du, dv, t, t_hi, expected = np.empty(b), np.empty(b), np.empty(b), np.empty(b), np.empty(b)
    active = np.empty(b, dtype=np.int64)
    out = np.empty(u0.shape[0])
    for i in range(u0.shape[0]):
        ch, sh = math.cos(heading[i]), math.sin(heading[i])
        for k in range(b):
            # the beam's direction by the angle-sum identities: no trigonometry per ray
            du[k] = ch * cb[k] - sh * sb[k]
            dv[k] = sh * cb[k] + ch * sb[k]
        trace_fan(clear, stride, width, height, u0[i], v0[i], du, dv, t_max, t, t_hi, active, expected)
        acc = 0.0
        for k in range(b):
            e = expected[k]
            e = min(e * resolution, range_max) if e != np.inf else range_max
            z = ranges[k] - e
            pz = z_hit * math.exp(-z * z * inv_two_var) + floor_p[k]
            if z < 0.0:
                pz += short[k]
            acc += pz * pz * pz
        out[i] = math.log1p(acc)
    return out


def beam_log_weights(
    tracer: ClearanceTracer,
    origins: np.ndarray,
    headings: np.ndarray,
    bearings: np.ndarray,
    ranges: np.ndarray,
    range_max: float,
    options: AmclOptions,
) -> np.ndarray:
    """(N,) beam-model log weights of laser poses ``origins`` (N, 2) map frame and ``headings``
    (N,), for readings ``ranges`` (B,) at ``bearings`` (B,) (``range_max`` for no return)."""
    clear, stride, width, height = tracer.tables
    g = tracer.geometry
    local = tracer.to_local(origins)
    mixture = np.array(
        [
            options.z_hit,
            options.z_short,
            options.z_max,
            options.z_rand,
            options.sigma_hit,
            options.lambda_short,
        ]
    )
    return _beam_log_weights(
        clear,
        stride,
        width,
        height,
        np.ascontiguousarray(local[:, 0]),
        np.ascontiguousarray(local[:, 1]),
        np.asarray(headings, dtype=np.float64) - g.origin.theta,
        np.asarray(bearings, dtype=np.float64),
        np.asarray(ranges, dtype=np.float64),
        float(range_max),
        g.resolution,
        mixture,
    )
