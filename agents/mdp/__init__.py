"""Finite MDPs and dynamic programming (thesis ch. 2.2-2.3), grid-map MDPs and
the POMDP belief filter. A plain library: numpy, scipy and numba only."""
