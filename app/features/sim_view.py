"""Show what only the simulator knows (people walking through the world) in the 3D view."""

from __future__ import annotations

from typing import Any

import numpy as np

ORDER = 95


class SimPeopleStage:
    """Publishes ``extras["people"]`` as (P, 4) x, y, heading, radius from the simulated crowd."""

    def __init__(self, people: Any) -> None:
        self.people = people

    def tick(self, session, frame, now) -> None:
        pass

    def snapshot_fields(self, session) -> dict[str, Any] | None:
        if len(self.people) == 0:
            return None
        poses = self.people.poses()
        return {"extras": {"people": np.column_stack((poses, self.people.radius[: len(poses)]))}}

    def close(self) -> None:
        pass


def setup(runtime) -> SimPeopleStage | None:
    people = getattr(runtime.session.driver, "people", None)
    if people is None:  # a real robot: nothing to show
        return None
    stage = SimPeopleStage(people)
    runtime.session.add_stage(stage)
    return stage
