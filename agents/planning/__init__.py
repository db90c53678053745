"""Planners (thesis ch. 3): exact grid A* and the modified A* over the robot's
own (cell, heading) lattice, with the expert controller that follows it."""

from agents.planning.astar import PathResult, astar, distance_field, path_length
from agents.planning.lattice import LatticeConfig, LatticePlan, plan_lattice

__all__ = [
    "LatticeConfig",
    "LatticePlan",
    "PathResult",
    "astar",
    "distance_field",
    "path_length",
    "plan_lattice",
]
