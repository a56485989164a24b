"""Where the shared datasets live (real robot logs, ROS maps, MovingAI scenarios), for the
benchmarks and the tests that read them.

One resolution used everywhere: ``NAVDECK_DATASETS`` (the datasets folder itself), else
``NAVDECK_SHARED_DIR/datasets``, else ``shared/datasets`` beside the repository (the workplace layout),
else ``/work/shared/datasets`` (a clone made elsewhere on the development machine). Callers check
``exists()`` and skip with a reason when the data is not there: none of it ships with the repository.
"""

from __future__ import annotations

import os
from pathlib import Path

_REPO = Path(__file__).resolve().parents[1]


def datasets_dir() -> Path:
    """The datasets folder, resolved as the module docstring says (it may not exist)."""
    if explicit := os.environ.get("NAVDECK_DATASETS"):
        return Path(explicit)
    if shared := os.environ.get("NAVDECK_SHARED_DIR"):
        return Path(shared) / "datasets"
    beside = _REPO.parent / "shared" / "datasets"
    return beside if beside.is_dir() else Path("/work/shared/datasets")


DATASETS = datasets_dir()
ROS_MAPS = DATASETS / "ros_maps"
SLAM_BENCHMARK = DATASETS / "slam_benchmark_2d"
MOVINGAI = DATASETS / "movingai"
TB3_MAP = ROS_MAPS / "turtlebot3_navigation2" / "map.yaml"
