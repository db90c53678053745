"""Screen of this record (validation only): ``bench.paired_outcomes`` with the own map's soft-band
penalty (``worlds.own_map.PENALTY``) set to P. The module constant is read when numba compiles the
subgoal search, so each P needs a cache directory of its own::

    PYTHONPATH=. NUMBA_CACHE_DIR=/tmp/nb-P python results/maps/clearance-band/penalty_screen.py P \\
        --cells 10 --sizes 48 --maps /work/shared/data/map_server/smoothers_world.yaml --out penalty_P.json
"""

import sys

import worlds.own_map as own_map

own_map.PENALTY = float(sys.argv[1])
from bench.paired_outcomes import main  # noqa: E402  (after the patch, before anything compiles)

raise SystemExit(main(sys.argv[2:]))
