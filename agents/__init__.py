"""Learning and planning: MDP toolkit, tabular RL, planners, imitation, NNQL, NIRL.
A plain library: never imports Zenoh or anything from ``services``."""
