"""Finite MDPs and dynamic programming (thesis ch. 2.2-2.3), grid-map MDPs with
a fast grid solver, and the POMDP belief filter with QMDP. A plain library:
numpy, scipy and numba only."""

from agents.mdp.dp import (
    SOLVERS,
    SolveResult,
    gauss_seidel_value_iteration,
    modified_policy_iteration,
    policy_evaluation,
    policy_iteration,
    q_value_iteration,
    stopping_threshold,
    value_iteration,
)
from agents.mdp.grid import default_start_goal, dynamics_to_mdp, grid_mdp
from agents.mdp.model import FiniteMDP, InvalidMDPError
from agents.mdp.pomdp import BeliefFilter, qmdp_action, wall_readings, wall_sensor_model
from agents.mdp.sweep import grid_value_iteration

__all__ = [
    "SOLVERS",
    "BeliefFilter",
    "FiniteMDP",
    "InvalidMDPError",
    "SolveResult",
    "default_start_goal",
    "dynamics_to_mdp",
    "gauss_seidel_value_iteration",
    "grid_mdp",
    "grid_value_iteration",
    "modified_policy_iteration",
    "policy_evaluation",
    "policy_iteration",
    "q_value_iteration",
    "qmdp_action",
    "stopping_threshold",
    "value_iteration",
    "wall_readings",
    "wall_sensor_model",
]
