"""The robot's own map: a grid on the map's cells, per robot and episode, written only from the
robot's own rays and poses (see :mod:`worlds.perception`), and the subgoal planned on it.

The plan grid a subgoal search reads is *padded* (the layout of :mod:`worlds.gridsearch`): one
flat uint8 row per robot, :data:`~worlds.fields.BLOCKED` on seen-blocked cells (own map) or
blocked cells (known map) and on a ring around the map.

**Configuration space.** The search plans for the robot's centre, so on maps whose cells are finer
than the robot it searches an *inflated* copy of the plan grid (``wide``), a small costmap in the
manner of ROS costmap_2d's / nav2's inflation layer (``nav2_costmap_2d::InflationLayer``): a cell
whose centre lies closer than the robot's radius to a blocked cell of the plan grid (the ring
included) is blocked (nav2's ``INSCRIBED_INFLATED_OBSTACLE``, which its grid planners refuse), and
a cell closer than the subgoal's clearance is :data:`~worlds.gridsearch.SOFT`: entering it costs
``1 +`` :data:`PENALTY` times the move (nav2's cost decaying beyond the inscribed radius, in one
step). So the path keeps the clearance from walls where that costs little, as a path through 1 m
cells keeps 0.5 m, and still takes a door narrower than twice the clearance rather than a long
detour. The levels, widest first (:func:`level_radius`): the clearance's (soft), the radius's
(blocked). Without inflation, at 0.1 m cells a path runs through gaps narrower than the robot and
along walls closer than its radius; at 1 m cells (the default radius 0.25 m, clearance 0.4 m)
nothing is inflated (:func:`inflation_cells` is 0) and nothing of the inflation runs. ``near``
counts, per level and cell, the blocked cells within its reach; :func:`_set` adds or takes one over
the disk around a cell whose blocked state changed, so the inflated grid follows the own map per
changed cell, as the plan grid does.

**Unseen cells.** The plan is optimistic: a cell the robot has not seen plans as free. With
``ObservationConfig.subgoal_prefers_seen`` (learned policies' default) the plan grid starts with every
cell :data:`~worlds.gridsearch.SOFT` (:func:`plan_clear`) and a cell turns free once a ray sees it free,
so the search enters an unseen cell at ``1 +`` :data:`PENALTY` times the move: the robot keeps to ways
it has seen unless an unseen one is clearly shorter, rather than trying one unseen shortcut after
another (issue 39: nearly every timeout on 64-cell room maps). :mod:`worlds.perceive` does so on maps
whose cells need no inflation only (0.8 m and more for the default robot): the own map marks free the
cells that one traced ray per sector crosses, which at 1 m cells is nearly every cell the robot looked
at, but at 0.1 m cells leaves most cells between the rays unseen (24 rays 15 degrees apart pass 0.26 m
apart 1 m out), and there the preference made the robot follow its own rays (validation smoothers_world
99 -> 95%, docs/navigation-by-size.md section 12). So unseen cells are :data:`SOFT` on the plan
grid only; an inflated grid (``wide``) does not hold them.
"""

from __future__ import annotations

import math

from numba import njit

from worlds.fields import BLOCKED
from worlds.gridsearch import DIAGONAL, GEN, SOFT, SQRT2, search_run, search_start

UNKNOWN, FREE, SEEN_BLOCKED = 0, 1, 2
"""cell states of the robot's own map"""


HIT_MARGIN = 1e-6
"""cells: a ray that hit something marks the cell this far past its end blocked (the cell it hit), and
its free trace stops this far short of its end, so no trace clears the cell a ray hit. Without the
margin the trace's boundary crossings, computed apart from the range, enter the hit cell a rounding
error before the range half the time and clear it: at 0.1 m cells 8.5% of the wall cells the rays had
marked were cleared again a step later (a heuristic's 150 steps on mixed:32 split 10x10), at 1 m
cells 0.15% (``tests/test_own_map_inflation.py``)."""

CHANGED, ON_PLAN = 1, 2
"""flags of :func:`map_rays`: a cell became blocked or stopped being blocked; one of them lies where
the last search (:func:`waypoint`) looked"""


@njit(cache=True)
def _band(reach):
    """:func:`inflation_cells` of a reach given in cells: ceil(reach - 0.5), at least 0."""
    return max(math.ceil(reach - 0.5), 0)


@njit(cache=True)
def inflation_cells(radius, cell):
    """How many cells the plan grid is inflated by for a robot of ``radius`` metres on cells of
    ``cell`` metres: the largest offset k (in rows or columns) at which a cell's centre can lie
    closer than ``radius`` to a blocked cell, k = ceil(radius / cell - 0.5) (a cell d rows away is
    (d - 0.5) cells from the centre). 0 at 1 m cells and the default 0.25 m radius: no inflation.
    Which cells of the (2k+1)^2 square count is :func:`_reaches`'s."""
    return _band(radius / cell)


LEVELS = 2
"""inflation levels at most: the subgoal's clearance (soft), then the robot's radius (blocked)"""
PENALTY = 1.0
"""a move into a cell of the clearance's band costs ``1 + PENALTY`` times its length: the path leaves
the band where a detour of up to that many times the band's length avoids it"""


@njit(cache=True)
def level_radius(radius, clearance, level):
    """The radius (m) of inflation level ``level`` (0: the widest; 0.0: no such level): the subgoal's
    clearance when it is wider than the robot's ``radius``, then the radius. The last level blocks,
    the one before it is soft (:func:`_value`); a map is inflated when :func:`inflation_cells` of the
    widest is above 0 on its cells."""
    if level == 0:
        return max(radius, clearance)
    if level == 1 and clearance > radius:
        return radius
    return 0.0


@njit(cache=True)
def _reaches(dr, dc, reach):
    """Does the centre of a cell ``dr`` rows and ``dc`` columns from a blocked cell lie closer than
    ``reach`` cells (the robot's radius over the cell size) to that cell's square?"""
    dy, dx = max(abs(dr) - 0.5, 0.0), max(abs(dc) - 0.5, 0.0)
    return dx * dx + dy * dy < reach * reach


@njit(cache=True)
def _value(near, at):
    """The inflated grid's value of padded map cell ``at`` from the levels' counts ``near``: blocked
    within the last level's reach (the robot's radius), :data:`SOFT` within another's, else free."""
    last = near.shape[0] - 1
    if near[last, at] > 0:
        return BLOCKED
    return SOFT if last > 0 and near[0, at] > 0 else 0


@njit(cache=True, _nrt=False)
def _spread(wide, near, level, stride, height, width, r, c, delta, reach, band):
    """Add ``delta`` (+1 or -1) to level ``level``'s count ``near`` of every map cell within ``reach``
    cells (``band``: :func:`inflation_cells`) of the padded cell (r, c) (-1 and height / width are the
    ring), and set those cells of ``wide`` (:func:`_value`)."""
    for rr in range(max(r - band, 0), min(r + band, height - 1) + 1):
        for cc in range(max(c - band, 0), min(c + band, width - 1) + 1):
            if _reaches(rr - r, cc - c, reach):
                at = (rr + 1) * stride + cc + 1
                near[level, at] += delta
                wide[at] = _value(near, at)


@njit(cache=True, _nrt=False)
def inflate(plan, wide, near, height, width, reach):
    """The inflated grid ``wide`` (and the levels' counts ``near``, one row per level, of reaches
    ``reach`` cells) of the padded plan grid ``plan`` from scratch: the ring blocked, each map cell
    :func:`_value` of the blocked cells of ``plan`` around it (see the module docstring). Nothing
    without a grid (``wide`` empty)."""
    if wide.shape[0] == 0:
        return
    stride = width + 2
    for at in range((height + 2) * stride):
        wide[at] = BLOCKED
        for level in range(near.shape[0]):
            near[level, at] = 0
    for r in range(height):
        for c in range(width):
            wide[(r + 1) * stride + c + 1] = 0
    for level in range(near.shape[0]):
        band = _band(reach[level])
        for r in range(-1, height + 1):
            for c in range(-1, width + 1):
                if plan[(r + 1) * stride + c + 1] == BLOCKED:
                    _spread(wide, near, level, stride, height, width, r, c, 1, reach[level], band)


@njit(cache=True)
def _set(occ, plan, exam, exam_id, stride, r, c, state, wide, near, height, reach):
    """Cell (r, c) of the own map becomes ``state``; the plan grid (if tracked: ``plan`` not empty)
    follows, and its inflated grid ``wide`` (empty: none; ``near``, ``reach``: see :func:`inflate`).
    An unseen cell that the plan grid holds :data:`SOFT` (:func:`plan_clear`) becomes free there once
    seen free. Returns :data:`CHANGED` | :data:`ON_PLAN` flags."""
    old = occ[r, c]
    occ[r, c] = state
    at = (r + 1) * stride + c + 1
    flipped = (old == SEEN_BLOCKED) != (state == SEEN_BLOCKED)
    seen_free = plan.shape[0] > 0 and plan[at] == SOFT and state == FREE  # an unseen plan cell seen free
    if not (flipped or seen_free):
        return 0
    levels = near.shape[0] if wide.shape[0] > 0 and flipped else 0  # the inflation follows blocked cells
    band = _band(reach[0]) if levels > 0 else 0  # the widest level's
    if plan.shape[0] > 0:
        plan[at] = BLOCKED if state == SEEN_BLOCKED else 0
        delta = 1 if state == SEEN_BLOCKED else -1
        for level in range(levels):
            lr = reach[level]
            _spread(wide, near, level, stride, height, stride - 2, r, c, delta, lr, _band(lr))
    if exam_id < 0:
        return CHANGED | ON_PLAN
    if band > 0:  # the inflated cells it changed lie within band: next to an expanded cell within band + 1
        for rr in range(max(r - band - 1, -1), min(r + band + 1, height) + 1):
            for cc in range(max(c - band - 1, -1), min(c + band + 1, stride - 2) + 1):
                if exam[(rr + 1) * stride + cc + 1] == exam_id:
                    return CHANGED | ON_PLAN
        return CHANGED
    for row in (at - stride, at, at + stride):
        if exam[row - 1] == exam_id or exam[row] == exam_id or exam[row + 1] == exam_id:
            return CHANGED | ON_PLAN  # next to a cell the search expanded: it read this one
    return CHANGED


@njit(cache=True, _nrt=False)
def map_rays(occ, visits, plan, exam, exam_id, height, width, cell, x, y, theta, ray_c, ray_s, ranges,
             max_range, per, wide, near, reach):  # fmt: skip
    """Write one step's rays and pose into a robot's own map ``occ`` (and its padded plan grid
    ``plan``, seen-blocked cells blocked, unknown and free ones free, when not empty): the cell
    past the end of every ray that hit something is blocked, the cells that the middle ray of each
    sector of ``per`` rays crosses before its end are free (rays of a sector cross nearly the same
    cells; tracing one keeps the map's cost near the sensor's). Returns flags: :data:`CHANGED`
    when a cell became blocked or stopped being blocked (unknown and free plan alike), with
    :data:`ON_PLAN` when such a cell lies next to one the search ``exam_id`` expanded (``exam``
    holds their stamps; ``exam_id < 0``: unknown, every change counts). The plan grid's inflated
    copy ``wide`` (empty: none) follows too (:func:`_set`)."""
    flags = 0
    stride = width + 2
    px, py = x / cell, y / cell
    if px < 0.0 or py < 0.0 or px >= width or py >= height:
        return 0
    c0, r0 = int(px), int(py)
    visits[r0, c0] += 1
    flags |= _set(occ, plan, exam, exam_id, stride, r0, c0, FREE, wide, near, height, reach)
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    for k in range(ray_c.shape[0]):
        dx = cos_t * ray_c[k] - sin_t * ray_s[k]
        dy = sin_t * ray_c[k] + cos_t * ray_s[k]
        length = ranges[k] / cell
        hit = ranges[k] < max_range
        if hit:
            hx, hy = px + (length + HIT_MARGIN) * dx, py + (length + HIT_MARGIN) * dy
            if 0.0 <= hx < width and 0.0 <= hy < height:
                flags |= _set(occ, plan, exam, exam_id, stride, int(hy), int(hx), SEEN_BLOCKED, wide, near,
                               height, reach)  # fmt: skip
        if k % per != per // 2:
            continue
        # exact traversal of the cells the ray crosses before its end (Amanatides & Woo)
        c, r = c0, r0
        step_c, step_r = (1 if dx > 0.0 else -1), (1 if dy > 0.0 else -1)
        inv_dx = 1.0 / dx if dx != 0.0 else math.inf
        inv_dy = 1.0 / dy if dy != 0.0 else math.inf
        next_c = (c + (1.0 if dx > 0.0 else 0.0) - px) * inv_dx if dx != 0.0 else math.inf
        next_r = (r + (1.0 if dy > 0.0 else 0.0) - py) * inv_dy if dy != 0.0 else math.inf
        delta_c, delta_r = abs(inv_dx), abs(inv_dy)
        stop = length - HIT_MARGIN if hit else length  # never clear the cell the ray hit
        while True:  # selects, not branches: which boundary comes next is a coin toss per cell
            on_c = next_c < next_r
            t = next_c if on_c else next_r
            c += step_c if on_c else 0
            r += 0 if on_c else step_r
            next_c = next_c + delta_c if on_c else next_c  # (not += 0.0: -0.0 would become 0.0)
            next_r = next_r if on_c else next_r + delta_r
            if t >= stop or c < 0 or r < 0 or c >= width or r >= height:
                break
            flags |= _set(occ, plan, exam, exam_id, stride, r, c, FREE, wide, near, height, reach)
    return flags


@njit(cache=True, _nrt=False)
def plan_clear(plan, height, width, unseen=0):
    """The padded plan grid of an empty own map: every cell ``unseen`` (0: free; :data:`SOFT`: the
    plan prefers cells the robot has seen, ``ObservationConfig.subgoal_prefers_seen``), the ring
    around it blocked."""
    stride = width + 2
    for k in range((height + 2) * stride):
        plan[k] = BLOCKED
    for r in range(height):
        for c in range(width):
            plan[(r + 1) * stride + c + 1] = unseen


@njit(cache=True, _nrt=False)
def plan_from_field(field, base, plan, height, width):
    """Copy the padded true map (the kernel's field of the map at ``base``) into ``plan``."""
    for k in range((height + 2) * (width + 2)):
        plan[k] = BLOCKED if field[base + k] == BLOCKED else 0


@njit(cache=True, _nrt=False)
def _in_clear(plan, stride, height, width, cell, x0, y0, x1, y1, clearance, exam, exam_id):
    """Does the segment (x0, y0) -> (x1, y1) stay at least ``clearance`` metres from every blocked cell
    of the padded grid ``plan`` (points every quarter cell, each against the cells around it)? The
    cells it reads get the stamp ``exam_id`` in ``exam`` (a change there must reach the plan)."""
    length = math.sqrt((x1 - x0) ** 2 + (y1 - y0) ** 2)
    samples = int(length / (0.25 * cell)) + 1
    for k in range(samples + 1):
        t = k / samples
        px, py = x0 + t * (x1 - x0), y0 + t * (y1 - y0)
        r0, r1 = max(math.floor((py - clearance) / cell), -1), min(int((py + clearance) / cell), height)
        c0, c1 = max(math.floor((px - clearance) / cell), -1), min(int((px + clearance) / cell), width)
        for r in range(r0, r1 + 1):
            for c in range(c0, c1 + 1):
                at = (r + 1) * stride + c + 1
                exam[at] = exam_id
                if plan[at] != BLOCKED:
                    continue
                dx = max(c * cell - px, 0.0, px - (c + 1) * cell)
                dy = max(r * cell - py, 0.0, py - (r + 1) * cell)
                if dx * dx + dy * dy < clearance * clearance:
                    return False
    return True


@njit(cache=True, _nrt=False)
def _open(wide, near, plan, stride, height, width, centre, band, opened):
    """Open (``opened``) the cells of the inflated grid ``wide`` within ``band`` rows and columns of the
    padded cell ``centre`` that are free on the plan grid (blocked ones become :data:`SOFT`: passable,
    at the band's cost), or set them again as the counts ``near`` say (:func:`_value`)."""
    r0, c0 = centre // stride - 1, centre % stride - 1
    for r in range(max(r0 - band, 0), min(r0 + band, height - 1) + 1):
        for c in range(max(c0 - band, 0), min(c0 + band, width - 1) + 1):
            at = (r + 1) * stride + c + 1
            if plan[at] != BLOCKED:
                wide[at] = SOFT if opened and wide[at] == BLOCKED else _value(near, at)


@njit(cache=True)
def _move(a, b, stride):
    """Length (cells) of the move between neighbouring padded cells ``a`` and ``b``."""
    d = abs(a - b)
    return SQRT2 if d == stride - 1 or d == stride + 1 else 1.0


@njit(cache=True, _nrt=False)
def waypoint(plan, wide, near, reach, height, width, cell, x, y, goal_r, goal_c, along, work, exam, exam_id,
             clearance=0.0, unseen=0.0):  # fmt: skip
    """A* (8-connected, no corner cutting) on the padded grid ``plan`` from the robot's cell to the
    goal cell (counted free); the centre of the cell ``along`` metres down the path, or the goal
    itself when the path ends first, the robot is off the map or on a blocked cell, or no path
    exists. With ``clearance`` > 0 the waypoint is the furthest cell of the path up to there that the
    straight line from the centre of the robot's cell reaches with that clearance from the blocked
    cells (the next cell of the path when none does): a waypoint never lies round a corner, so
    heading for it does not cut the corner (a door's jamb). ``work``: the search's work arrays
    (:func:`worlds.gridsearch.new_work`). The cells it
    expanded get the stamp ``exam_id`` in ``exam`` (a search reads only their 3x3 neighbourhoods,
    so changes elsewhere leave its result as it is). Returns (the waypoint's padded cell, -1 for the
    goal itself; searched; the path's length in metres from the robot's cell to the goal's, -1.0
    when there is no path or no search).

    With an inflated grid ``wide`` (:func:`inflate`; empty: none; ``near``, ``reach``: its levels'
    counts and reaches) the search runs on it first, its :data:`SOFT` cells at ``1 +`` :data:`PENALTY`
    times a move's cost; the cells within the robot's radius of the robot's cell and of the goal's
    that are free on the plan grid count soft (:func:`_open`): a robot whose cell centre lies within
    its radius of a wall still finds the way out, away from the wall (``band`` cells straight away
    from it lie beyond the reach), and a goal beside a wall is still reached. The waypoint and the
    length are then measured along the path in metres, not in its costs. When it finds no path (a
    gap that the cell rounding closed), the search runs again on ``plan``, so the subgoal is never
    lost to the inflation. The clearance check reads ``plan`` either way.

    With ``unseen`` > 0 the search on ``plan`` enters its :data:`SOFT` cells (the cells the robot has
    not seen, :func:`plan_clear`) at ``1 + unseen`` times a move's cost, and the waypoint and the length
    are measured in metres, as on the inflated grid."""
    g, parent, seen, order, meta = work[0], work[1], work[3], work[7], work[8]
    stride = width + 2
    c, r = int(x / cell), int(y / cell)
    if c < 0 or r < 0 or c >= width or r >= height:
        return -1, False, -1.0
    start, goal = (r + 1) * stride + c + 1, (goal_r + 1) * stride + goal_c + 1
    if plan[start] == BLOCKED:
        return -1, False, -1.0
    found = False
    if wide.shape[0] > 0:
        band = _band(reach[near.shape[0] - 1])  # the robot's radius
        _open(wide, near, plan, stride, height, width, start, band, True)
        _open(wide, near, plan, stride, height, width, goal, band, True)
        was_goal = wide[goal]
        wide[goal] = 0  # counted free, as on the plan grid
        search_start(start, goal, stride, DIAGONAL, *work)
        expanded = search_run(wide, 0, stride, goal, DIAGONAL, *work, PENALTY)
        wide[goal] = was_goal
        _open(wide, near, plan, stride, height, width, goal, band, False)
        _open(wide, near, plan, stride, height, width, start, band, False)
        for k in range(expanded):
            exam[order[k]] = exam_id
        found = seen[goal] == meta[GEN]
    measured = found  # the path's costs are not its length: measure it
    if not found:
        was = plan[goal]
        plan[goal] = 0
        search_start(start, goal, stride, DIAGONAL, *work)
        expanded = search_run(plan, 0, stride, goal, DIAGONAL, *work, unseen)
        plan[goal] = was
        for k in range(expanded):
            exam[order[k]] = exam_id
        if seen[goal] != meta[GEN]:
            return -1, True, -1.0
        measured = unseen > 0.0  # unseen cells cost more than their length too
    if measured:  # measure the path, then walk back from the goal to the cell ``along`` metres from
        # the start (the first whose predecessor is nearer than that)
        total, node = 0.0, goal
        while parent[node] >= 0:
            total += _move(node, parent[node], stride)
            node = parent[node]
        node, from_goal = goal, 0.0
        while parent[node] >= 0:
            step = _move(node, parent[node], stride)
            if (total - from_goal - step) * cell < along:
                break
            from_goal += step
            node = parent[node]
        length = total
    else:
        # parent links run goal -> start: the node at path length >= along is the last one walking back
        # from the goal whose g is still >= along (g grows along the path from the start)
        node, length = goal, g[goal]
        while parent[node] >= 0 and g[parent[node]] * cell >= along:
            node = parent[node]
    if clearance > 0.0 and node != start:
        sx, sy = (c + 0.5) * cell, (r + 0.5) * cell
        while parent[node] >= 0 and parent[node] != start:
            if node == goal:
                nx, ny = (goal_c + 0.5) * cell, (goal_r + 0.5) * cell
            else:
                nx, ny = (node % stride - 1 + 0.5) * cell, (node // stride - 1 + 0.5) * cell
            if _in_clear(plan, stride, height, width, cell, sx, sy, nx, ny, clearance, exam, exam_id):
                break
            node = parent[node]
    return (-1 if node == goal else node), True, length * cell


@njit(cache=True)
def centre(node, width, cell, gx, gy):
    """The point a :func:`waypoint` cell stands for: its centre, or the goal (gx, gy) for -1."""
    if node < 0:
        return gx, gy
    stride = width + 2
    return (node % stride - 1 + 0.5) * cell, (node // stride - 1 + 0.5) * cell
