"""Collision events of the ego car against the town and the traffic (MuJoCo's collision pass)."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco

from vlocbench.sim.scene import TownScene


@dataclass(frozen=True)
class CollisionEvent:
    """The ego car started touching ``label`` at ``time_s`` near (x_m, y_m).

    ``category``: building, tree, pole, parked_car, curb, edge (the town's), car (traffic) or
    pedestrian.
    """

    time_s: float
    x_m: float
    y_m: float
    category: str
    label: str


def touching(scene: TownScene) -> dict[str, tuple[str, float, float]]:
    """Everything the ego car touches now: label -> (category, contact x, contact y).

    Expects ``scene.forward()`` to have run after the last pose change.
    """
    m, d = scene.model, scene.data
    mujoco.mj_collision(m, d)
    hits: dict[str, tuple[str, float, float]] = {}
    for k in range(d.ncon):
        c = d.contact[k]
        for g in (c.geom1, c.geom2):
            info = scene.geom_info.get(int(g))
            if info is not None and info[1] not in hits:
                hits[info[1]] = (info[0], float(c.pos[0]), float(c.pos[1]))
    return hits
