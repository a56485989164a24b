"""A run as JSON (everything, columns as arrays) or CSV (one row per trajectory sample)."""

from __future__ import annotations

import csv
import io
import math

import numpy as np

from app.export.data import RunData
from app.runs.codec import MODES, SAMPLE_DTYPE

CSV_COLUMNS = [n for n in SAMPLE_DTYPE.names if n not in ("mode", "behavior")] + ["mode", "behavior"]


def _clean(v: float) -> float | None:
    """JSON has no NaN/inf: unknown values become null."""
    return float(v) if math.isfinite(v) else None


def samples_columns(samples: np.ndarray, labels: list[str], digits: int = 4) -> dict[str, list]:
    """Column-wise samples (the Runs page plots and the JSON export use this shape)."""
    out: dict[str, list] = {}
    for name in SAMPLE_DTYPE.names:
        if name in ("mode", "behavior"):
            continue
        col = np.round(samples[name].astype(np.float64), 3 if name == "t" else digits)
        out[name] = [_clean(v) for v in col.tolist()]
    out["mode"] = [MODES[i] if i < len(MODES) else str(i) for i in samples["mode"].tolist()]
    out["behavior"] = [
        labels[i] if i < len(labels) and labels[i] else None for i in samples["behavior"].tolist()
    ]
    return out


def run_json(data: RunData, *, with_scans: bool = False) -> dict:
    """The whole run as one JSON document (scans optional: they dominate the size)."""
    doc: dict = {
        "partial": data.partial,
        "run": data.run,
        "events": data.events,
        "goals": data.goals,
        "samples": samples_columns(data.samples, data.labels),
        "plans": [{"t": t, "poses": np.round(p, 4).tolist()} for t, p in data.plans],
        "maps": [
            {
                "t": t,
                "version": v,
                "resolution": g.resolution,
                "width": g.geometry.width,
                "height": g.geometry.height,
                "origin": [g.geometry.origin.x, g.geometry.origin.y, g.geometry.origin.theta],
            }
            for t, v, g in data.grids
        ],
    }
    if with_scans:
        doc["scans"] = [
            {
                "t": t,
                "angle_min": s.angle_min,
                "angle_increment": s.angle_increment,
                "range_min": s.range_min,
                "range_max": s.range_max,
                "ranges": [_clean(r) for r in np.round(s.ranges.astype(np.float64), 3).tolist()],
            }
            for t, s in data.scans
        ]
    return doc


def samples_csv(data: RunData) -> str:
    cols = samples_columns(data.samples, data.labels)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    n = data.samples.shape[0]
    for i in range(n):
        w.writerow(["" if cols[c][i] is None else cols[c][i] for c in CSV_COLUMNS])
    return buf.getvalue()
