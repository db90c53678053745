"""Diagnostic of this record (validation only): ``bench.paired_outcomes`` with the plan grid inflated by
R metres in one level instead of the robot's radius, on the tree of b383bdc (one level, plain fallback).
The robot's radius parameter of the perception is overwritten after it is built, so the inflation (and
nothing else: the world's collision radius is the kernel's) uses R::

    PYTHONPATH=<tree> python results/maps/clearance-band/single_level.py 0.4 --cells 10 \\
        --maps /work/shared/data/map_server/smoothers_world.yaml --out r0.4.json
"""

import sys

import worlds.perception as perception
from worlds.perceive import RADIUS_PARAM

R = float(sys.argv[1])
_built = perception.Perception.__init__


def _init(self, n, config, reuse=True):
    _built(self, n, config, reuse)
    self.params[RADIUS_PARAM] = R


perception.Perception.__init__ = _init
from bench.paired_outcomes import main  # noqa: E402  (after the patch, as the evaluation builds perceptions)

raise SystemExit(main(sys.argv[2:]))
