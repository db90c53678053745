"""The compiled step of the navigation world: one call moves every robot, checks its
motion for collisions, moves its discs, casts its beams, scores the step and (for the
vector env) resets finished robots. The single env calls the same functions with one
robot, so both envs are the same program.

The entry points take arrays grouped in tuples built by :class:`worlds.batch.NavBatch`:
``maps`` and ``entries`` (from :class:`worlds.bank.MapBank`), ``robots`` (per-robot state,
incl. its random stream and the range of pool entries it draws episodes from), ``discs``
(per-robot moving discs) and ``finals`` (terminal results of auto-reset robots). They
unpack them once; the per-robot helpers take plain arrays, because taking arrays out of
a tuple inside the robot loop costs reference counting on every robot (measured: it
doubled the cost of a step).

The entry points are compiled without numba's reference-counted runtime (``_nrt=False``):
they allocate nothing, and with it every array handed to an inlined helper costs an atomic
increment and decrement per robot (about 50 per robot-step: 8 ray casts, 10 Gaussian draws,
``_step`` and ``_observe`` arguments), measured as a quarter of the step's time. Without it
numba emits no reference counting, and the arrays stay alive because the caller holds them.

First compile (bench/first_run.py, results/first-run/): every distinct argument type a compiled
function is called with is one more compile of it, and a plain ``0``, ``-1`` or ``False`` in a
call is typed as that literal value, so the constants handed to compiled helpers are numpy
scalars (:data:`FIRST_ROBOT`, :data:`DRAW_ENTRY`, :data:`NEW_DISCS`: one specialisation each, the
same as a call from Python); :func:`_reset` (rare: once per episode) is compiled once and
called, not inlined into both :func:`step_range` and :func:`reset_some`; and the world's helpers
(here and in sensors, robot, obstacles, own_map, perceive, geodesic, gridsearch) are plain compiled
functions that their callers call, not numba's IR-level ``inline="always"``, which types and
lowers the helper's body again at every call site (``_relax`` 8 times in one search, ``_observe``
in both the step and the reset): without it a cold compile takes less CPU time and the step is
as fast (results/first-run/). Only the random draws (:mod:`worlds.rng`) stay inlined.

numba caches compiled code per source file and does not notice edits to the modules a
function calls; :func:`_drop_stale_cache` clears the cache when any of them changed.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
from numba import njit

from worlds.bank import E_CN, E_COFF, E_GC, E_GR, E_LIMIT, E_MAP, E_MIN_D2, E_RESAMPLE, E_SC, E_SR
from worlds.config import NavConfig
from worlds.gridsearch import DIAGONAL, GEN, search_run, search_start
from worlds.obstacles import move_disc, place_discs, swept_contact
from worlds.outcomes import Outcome
from worlds.rng import gauss, randint, uniform
from worlds.robot import capsule_hits_grid, held
from worlds.sensors import cast_along, ray_disc, ray_origin, reciprocal


def _drop_stale_cache() -> None:
    here = Path(__file__).parent
    sources = ("kernel.py", "obstacles.py", "rng.py", "robot.py", "sensors.py")
    sources += ("perception.py", "perceive.py", "own_map.py", "geodesic.py", "gridsearch.py", "fields.py")
    digest = hashlib.sha256(b"".join((here / name).read_bytes() for name in sources)).hexdigest()
    stamp = here / "__pycache__" / "kernel_sources.sha256"
    try:
        if stamp.exists() and stamp.read_text() == digest:
            return
        for stale in (here / "__pycache__").glob("*.nb[ic]"):
            stale.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest)
    except OSError:  # read-only install: numba then compiles in memory or elsewhere
        pass


_drop_stale_cache()

# indices into the float64 parameter vector built by make_params
P_STEP, P_RADIUS, P_TNOISE, P_RNOISE, P_HEADINGS, P_MAXR, P_SNOISE = range(7)
P_DROP, P_RGOAL, P_RCOLL, P_RSTEP, P_RPROG, P_MAXSTEPS, P_GOALTOL = range(7, 14)
P_OCOUNT, P_ORAD, P_OSPEED, P_OPATROL, P_OLENGTH, P_OSPAWN = range(14, 20)
P_PER = 20  # rays per range reading (sector)
P_OMIX = 21  # 1.0: each episode draws its disc count from 0..P_OCOUNT
P_STEPFACTOR = 22  # the step limit's factor on the A* path's steps (worlds.config.step_limit)
P_HELD = 23  # RobotConfig.held_headings: the heading turned to the nearest of this many before an action

RUNNING, GOAL = int(Outcome.RUNNING), int(Outcome.GOAL)
HIT_STATIC, HIT_DYNAMIC, TIMEOUT = (
    int(Outcome.COLLISION_STATIC),
    int(Outcome.COLLISION_DYNAMIC),
    int(Outcome.TIMEOUT),
)
TWO_PI = 2.0 * math.pi
FIRST_ROBOT = np.int64(0)
"""step_all's first robot, a numpy scalar: a literal 0 would compile step_range a second time"""
DRAW_ENTRY = np.int64(-1)
"""_reset's ``forced`` for "draw a pool entry", a numpy scalar (one compile of _reset)"""
NEW_DISCS = np.bool_(False)
"""_reset's ``keep_discs`` for an auto-reset, a numpy scalar (one compile of _reset)"""


def make_params(config: NavConfig) -> np.ndarray:
    r, s, w, o = config.robot, config.sensors, config.rewards, config.obstacles
    values = [r.step, r.radius, r.trans_noise, r.rot_noise, r.heading_choices, s.max_range, s.noise_std]
    values += [
        s.dropout_prob,
        w.goal,
        w.collision,
        w.step,
        w.progress,
        config.max_steps,
        config.goal_tolerance,
    ]
    values += [o.count, o.radius, o.speed, float(o.mode == "patrol"), o.patrol_length, o.spawn_clearance]
    values += [s.rays_per_beam, float(o.mix), config.step_factor, r.held_headings]
    return np.asarray(values, dtype=np.float64)


@njit(cache=True)
def _wrap(angle: float) -> float:
    while angle >= math.pi:
        angle -= TWO_PI
    while angle < -math.pi:
        angle += TWO_PI
    return angle


@njit(cache=True)
def _observe(i, field, moff, mh, mw, mcell, mp, x, y, c, s, gx, gy, rng, ox, oy, orad, ocount, params, beams,
             obs, rays):  # fmt: skip
    """Write robot ``i``'s observation: range readings / max_range (each the minimum of its sector's
    rays; ``beams = (beam_c, beam_s, dx, dy, inv_dx, inv_dy)``: every ray's direction relative to the
    heading, sector by sector, and work rows of the ray count), squashed goal distance, sin and cos
    of the goal bearing relative to the heading (``c``, ``s``: cosine and sine of the heading,
    already known to the caller). The noise-free range of every ray goes to ``rays[i]`` (metres)
    for the robot's own map (worlds.perception)."""
    beam_c, beam_s, ray_dx, ray_dy, inv_dx, inv_dy = beams
    m = mp[i]
    off, height, width, cell = moff[m], mh[m], mw[m], mcell[m]
    max_range, noise, drop = params[P_MAXR], params[P_SNOISE], params[P_DROP]
    per = int(params[P_PER])
    xi, yi = x[i], y[i]
    n_rays = beam_c.shape[0]
    n_beams = n_rays // per
    idx, col, row, px, py = ray_origin(field, off, height, width, cell, xi, yi)
    limit = max_range / cell
    # every ray's direction, then their reciprocals, each in a loop of its own (the divisions then
    # run side by side instead of at the head of each ray's traversal: measured ~15% off the rays)
    for k in range(n_rays):
        ray_dx[k] = c * beam_c[k] - s * beam_s[k]
        ray_dy[k] = s * beam_c[k] + c * beam_s[k]
    for k in range(n_rays):
        inv_dx[k], inv_dy[k] = reciprocal(ray_dx[k]), reciprocal(ray_dy[k])
    for b in range(n_beams):
        d = max_range
        for k in range(b * per, (b + 1) * per):
            dx, dy = ray_dx[k], ray_dy[k]
            r = 0.0
            if idx >= 0:
                r = cast_along(field, off, width, idx, col, row, px, py, dx, dy, inv_dx[k], inv_dy[k], limit)
                r = min(r * cell, max_range)
            for j in range(ocount[i]):
                r = min(r, ray_disc(xi, yi, dx, dy, ox[i, j], oy[i, j], orad[i, j]))
            rays[i, k] = r
            d = min(d, r)
        if noise > 0.0:
            d = min(max(d + noise * gauss(rng, i), 0.0), max_range)
        if drop > 0.0 and uniform(rng, i) < drop:
            d = max_range
        obs[i, b] = d / max_range
    ux, uy = gx[i] - xi, gy[i] - yi
    dist = math.sqrt(ux * ux + uy * uy)  # not hypot: nothing to overflow here, and cheaper
    obs[i, n_beams] = dist / (dist + max_range)
    if dist > 0.0:
        obs[i, n_beams + 1] = (-ux * s + uy * c) / dist
        obs[i, n_beams + 2] = (ux * c + uy * s) / dist
    else:
        obs[i, n_beams + 1] = 0.0
        obs[i, n_beams + 2] = 1.0


@njit(cache=True)
def _step(
    i, action, field, moff, mh, mw, mcell, mp, x, y, th, gx, gy, rng, steps, plen, pdist, outcome, discs,
    n_discs, params, turns, limit
):  # fmt: skip
    """Move robot ``i`` and its ``n_discs`` discs one step; set its outcome; return its reward and
    the cosine and sine of its new heading (for :func:`_observe`).
    (At most 30 arguments: CPython passes longer calls as ``*args``. The disc arrays stay in a
    tuple, opened only for robots that have discs.)"""
    m = mp[i]
    off, height, width, cell = moff[m], mh[m], mw[m], mcell[m]
    radius = params[P_RADIUS]
    turn_around = action == turns.shape[0]  # RobotConfig.turn_around: half a turn in place, no drive
    heading = held(th[i], params[P_HELD]) + (math.pi if turn_around else turns[action])
    if params[P_RNOISE] > 0.0:
        heading += params[P_RNOISE] * gauss(rng, i)
    distance = 0.0 if turn_around else params[P_STEP]
    if params[P_TNOISE] > 0.0 and not turn_around:
        distance = max(distance + params[P_TNOISE] * gauss(rng, i), 0.0)
    heading = _wrap(heading)
    th[i] = heading
    x0, y0 = x[i], y[i]
    c, s = math.cos(heading), math.sin(heading)
    x1, y1 = x0 + distance * c, y0 + distance * s
    result = RUNNING
    if capsule_hits_grid(field, off, height, width, cell, x0, y0, x1, y1, radius):
        result = HIT_STATIC
    for k in range(n_discs):
        ox, oy, ovx, ovy, orad, opat, oax, oay, obx, oby = discs
        px, py = ox[i, k], oy[i, k]
        ox[i, k], oy[i, k], ovx[i, k], ovy[i, k] = move_disc(
            field, off, height, width, cell, px, py, ovx[i, k], ovy[i, k], orad[i, k], opat[i, k],
            oax[i, k], oay[i, k], obx[i, k], oby[i, k],
        )  # fmt: skip
        reach = radius + orad[i, k]
        if result == RUNNING and swept_contact(x0, y0, x1, y1, px, py, ox[i, k], oy[i, k], reach):
            result = HIT_DYNAMIC
    reward = params[P_RSTEP]
    if result == RUNNING:
        x[i], y[i] = x1, y1
        plen[i] += distance
        ux, uy = gx[i] - x1, gy[i] - y1
        dist = math.sqrt(ux * ux + uy * uy)
        reward += params[P_RPROG] * (pdist[i] - dist)
        pdist[i] = dist
        if dist <= params[P_GOALTOL]:
            result = GOAL
            reward += params[P_RGOAL]
    else:
        reward += params[P_RCOLL]
    steps[i] += 1
    if result == RUNNING and steps[i] >= abs(limit[i]):
        result = TIMEOUT
    outcome[i] = result
    return reward, c, s


@njit(cache=True)
def _limit(field, off, height, width, cell, sr, sc, gr, gc, params, search) -> int:
    """The step limit of an episode from cell (sr, sc) to (gr, gc) (worlds.config.step_limit): an A*
    on the map's padded field (:mod:`worlds.gridsearch`, in the work arrays ``search``)."""
    floor = int(params[P_MAXSTEPS])
    if params[P_STEPFACTOR] <= 0.0:
        return floor
    g, parent, pos, seen, heap, key_f, key_g, order, meta = search
    stride = width + 2
    start, goal = (sr + 1) * stride + sc + 1, (gr + 1) * stride + gc + 1
    search_start(start, goal, stride, DIAGONAL, g, parent, pos, seen, heap, key_f, key_g, order, meta)
    search_run(field, off, stride, goal, DIAGONAL, g, parent, pos, seen, heap, key_f, key_g, order, meta)
    if seen[goal] != meta[GEN] or pos[goal] != -2:  # not reached: the floor
        return floor
    steps = math.ceil(params[P_STEPFACTOR] * g[goal] * cell / params[P_STEP] - 1e-9)
    return max(floor, steps)


@njit(cache=True)
def _settle_limit(i, maps, entries, ent, scell, gcell, mp, outcome, steps, params, limit, search) -> None:
    """Robot ``i`` timed out at the floor ``max_steps`` before its limit was known (negative): compute
    it now (:func:`_limit`; kept in the entry's ``E_LIMIT`` when the endpoints are the entry's) and
    let the episode run on if the path allows more steps. Lazy, because most episodes on small maps
    end before the floor and a search at every reset cost a third of the world's speed."""
    field, moff, mh, mw, mcell = maps
    etab = entries[0]
    m, j = mp[i], ent[i]
    sr, sc, gr, gc = scell[i, 0], scell[i, 1], gcell[i, 0], gcell[i, 1]
    limit[i] = _limit(field, moff[m], mh[m], mw[m], mcell[m], sr, sc, gr, gc, params, search)
    if sr == etab[j, E_SR] and sc == etab[j, E_SC] and gr == etab[j, E_GR] and gc == etab[j, E_GC]:
        etab[j, E_LIMIT] = limit[i]  # the same value whoever computes it: a cache
    if steps[i] < limit[i]:
        outcome[i] = RUNNING


MAX_START_DRAWS = 64
"""pool draws tried for a start with a drivable heading before the last one is kept anyway"""


@njit(cache=True)
def _drivable(field, off, height, width, cell, x, y, heading, params, turns) -> bool:
    """Has a robot at (x, y) facing ``heading`` an action whose noise-free motion is collision-free?"""
    step, radius = params[P_STEP], params[P_RADIUS]
    for a in range(turns.shape[0]):
        h = heading + turns[a]
        x1, y1 = x + step * math.cos(h), y + step * math.sin(h)
        if not capsule_hits_grid(field, off, height, width, cell, x, y, x1, y1, radius):
            return True
    return False


@njit(cache=True)
def start_heading(field, off, height, width, cell, x, y, sampled, params, turns) -> float:
    """The start heading: ``sampled`` when some action is collision-free from it, else the nearest
    drivable one among ``sampled + k * 2pi/n`` (k = 1, -1, 2, -2, ...; n = max(heading_choices,
    8)); NaN when none is. No random draws, so the result is fixed by the seed."""
    n = max(int(params[P_HEADINGS]), 8)
    for k in range(n):
        offset = (k + 1) // 2 * (1 if k % 2 == 1 else -1)
        heading = _wrap(sampled + offset * (TWO_PI / n))
        if _drivable(field, off, height, width, cell, x, y, heading, params, turns):
            return heading
    return math.nan


@njit(cache=True, _nrt=False)
def _reset(
    i, forced, keep_discs, maps, entries, mp, x, y, th, gx, gy, rng, steps, plen, pdist, outcome, ent, scell,
    gcell, plo, pn, moving, ocount, params, turns, beams, obs, rays, limit, search
) -> bool:  # fmt: skip
    """Start a new episode for robot ``i``: entry ``forced`` (or a random pool entry when
    negative, with fresh random endpoints if the entry allows), a random initial heading made
    drivable by :func:`start_heading`, new discs unless ``keep_discs``; then observe. A pool
    draw whose start has no drivable heading is redrawn (at most :data:`MAX_START_DRAWS`
    draws). Its step limit goes to ``limit[i]``: the entry's ``E_LIMIT`` when known, else minus the
    floor ``max_steps``, computed by :func:`_settle_limit` only if the episode lasts that long.
    Returns False when the start kept has no drivable heading. (Resets are rare, so the map tables
    may stay in their tuples here, and it is called rather than inlined: one compile serves
    step_range and reset_some.)"""
    field, moff, mh, mw, mcell = maps
    etab, cand = entries
    ox, oy, orad = moving[0], moving[1], moving[4]
    choices = int(params[P_HEADINGS])
    for _ in range(1 if forced >= 0 else MAX_START_DRAWS):
        j = forced if forced >= 0 else plo[i] + randint(rng, i, pn[i])
        m = etab[j, E_MAP]
        width, cell = mw[m], mcell[m]
        sr, sc, gr, gc = etab[j, E_SR], etab[j, E_SC], etab[j, E_GR], etab[j, E_GC]
        c_off, c_n = etab[j, E_COFF], etab[j, E_CN]
        if forced < 0 and etab[j, E_RESAMPLE]:
            s_idx = cand[c_off + randint(rng, i, c_n)]
            for _ in range(32):
                g_idx = cand[c_off + randint(rng, i, c_n)]
                dr, dc = s_idx // width - g_idx // width, s_idx % width - g_idx % width
                if dr * dr + dc * dc >= etab[j, E_MIN_D2]:
                    sr, sc, gr, gc = s_idx // width, s_idx % width, g_idx // width, g_idx % width
                    break
        xs, ys = (sc + 0.5) * cell, (sr + 0.5) * cell
        sampled = randint(rng, i, choices) * (TWO_PI / choices) if choices > 0 else TWO_PI * uniform(rng, i)
        heading = start_heading(field, moff[m], mh[m], width, cell, xs, ys, sampled, params, turns)
        if not math.isnan(heading):
            break
    drivable = not math.isnan(heading)
    ent[i] = j
    mp[i] = m
    scell[i, 0], scell[i, 1], gcell[i, 0], gcell[i, 1] = sr, sc, gr, gc
    x[i], y[i] = xs, ys
    gx[i], gy[i] = (gc + 0.5) * cell, (gr + 0.5) * cell
    th[i] = heading if drivable else _wrap(sampled)
    steps[i] = 0
    own = sr == etab[j, E_SR] and sc == etab[j, E_SC] and gr == etab[j, E_GR] and gc == etab[j, E_GC]
    limit[i] = etab[j, E_LIMIT] if own and etab[j, E_LIMIT] >= 0 else -int(params[P_MAXSTEPS])
    plen[i] = 0.0
    pdist[i] = math.hypot(gx[i] - x[i], gy[i] - y[i])
    outcome[i] = RUNNING
    if not keep_discs and params[P_OCOUNT] == 0.0:
        ocount[i] = 0
    elif not keep_discs:
        count = min(int(params[P_OCOUNT]), ox.shape[1])
        if params[P_OMIX] > 0.0:
            count = randint(rng, i, count + 1)
        spec = (count, params[P_ORAD], params[P_OSPEED], params[P_OPATROL] > 0.0, params[P_OLENGTH])
        keep_out = params[P_RADIUS] + params[P_ORAD] + params[P_OSPAWN]
        ocount[i] = place_discs(
            i, rng, field, moff[m], mh[m], width, cell, cand, c_off, c_n, x[i], y[i], keep_out, spec, moving
        )
    _observe(
        i, field, moff, mh, mw, mcell, mp, x, y, math.cos(th[i]), math.sin(th[i]), gx, gy, rng, ox, oy, orad,
        ocount, params, beams, obs, rays,
    )  # fmt: skip
    return drivable


@njit(cache=True, _nrt=False)
def step_all(actions, autoreset, maps, entries, robots, discs, params, turns, beams, obs, rays,
             reward, terminated, truncated, finals, search):  # fmt: skip
    """Step every robot; with ``autoreset``, a finished robot's terminal observation and results
    go to ``finals`` and it starts its next episode in the same call. Returns the number done."""
    return step_range(
        FIRST_ROBOT, actions.shape[0], actions, autoreset, maps, entries, robots, discs, params, turns, beams,
        obs, rays, reward, terminated, truncated, finals, search,
    )  # fmt: skip


@njit(cache=True, nogil=True, _nrt=False)
def step_range(lo, hi, actions, autoreset, maps, entries, robots, discs, params, turns, beams, obs,
               rays, reward, terminated, truncated, finals, search):  # fmt: skip
    """The work of :func:`step_all` for robots ``lo .. hi - 1``. Releases the GIL: robots share
    nothing they write and each owns its random stream, so threads may step disjoint ranges at
    once with results equal to :func:`step_all`'s (see :class:`worlds.batch.NavBatch`)."""
    field, moff, mh, mw, mcell = maps
    x, y, th, gx, gy, steps, plen, pdist, ent, scell, gcell, outcome, rng, plo, pn, mp, limit = robots
    ox, oy, orad, ocount = discs[0], discs[1], discs[4], discs[10]
    moving = discs[:10]
    f_obs, f_rays, f_outcome, f_plen, f_steps, f_pose, f_ent, f_scell, f_gcell, f_done = finals
    n_done = 0
    for i in range(lo, hi):
        reward[i], c, s = _step(
            i, actions[i], field, moff, mh, mw, mcell, mp, x, y, th, gx, gy, rng, steps, plen, pdist, outcome,
            moving, ocount[i], params, turns, limit,
        )  # fmt: skip
        if outcome[i] == TIMEOUT and limit[i] < 0:
            _settle_limit(i, maps, entries, ent, scell, gcell, mp, outcome, steps, params, limit, search)
        _observe(
            i, field, moff, mh, mw, mcell, mp, x, y, c, s, gx, gy, rng, ox, oy, orad, ocount, params, beams,
            obs, rays
        )  # fmt: skip
        result = outcome[i]
        terminated[i] = result in (GOAL, HIT_STATIC, HIT_DYNAMIC)
        truncated[i] = result == TIMEOUT
        done = result != RUNNING
        f_done[i] = done
        if done:
            n_done += 1
            if autoreset:
                for k in range(obs.shape[1]):  # no slice copy: it needs NRT
                    f_obs[i, k] = obs[i, k]
                for k in range(rays.shape[1]):
                    f_rays[i, k] = rays[i, k]
                f_outcome[i], f_plen[i], f_steps[i] = result, plen[i], steps[i]
                f_pose[i, 0], f_pose[i, 1], f_pose[i, 2] = x[i], y[i], th[i]
                f_ent[i] = ent[i]
                f_scell[i, 0], f_scell[i, 1] = scell[i, 0], scell[i, 1]
                f_gcell[i, 0], f_gcell[i, 1] = gcell[i, 0], gcell[i, 1]
                _reset(
                    i, DRAW_ENTRY, NEW_DISCS, maps, entries, mp, x, y, th, gx, gy, rng, steps, plen, pdist,
                    outcome, ent, scell, gcell, plo, pn, moving, ocount, params, turns, beams, obs, rays,
                    limit, search,
                )  # fmt: skip
    return n_done


@njit(cache=True, _nrt=False)
def reset_some(indices, forced, keep_discs, maps, entries, robots, discs, params, turns, beams, obs,
               rays, drivable, search):  # fmt: skip
    """Start new episodes for robots ``indices`` (see :func:`_reset` for ``forced``/``keep_discs``);
    ``drivable[n]`` tells whether robot ``indices[n]`` got a start with a drivable heading."""
    x, y, th, gx, gy, steps, plen, pdist, ent, scell, gcell, outcome, rng, plo, pn, mp, limit = robots
    ocount = discs[10]
    moving = discs[:10]
    for n in range(indices.shape[0]):
        drivable[n] = _reset(
            indices[n], forced[n], keep_discs[n], maps, entries, mp, x, y, th, gx, gy, rng, steps, plen,
            pdist, outcome, ent, scell, gcell, plo, pn, moving, ocount, params, turns, beams, obs,
            rays, limit, search,
        )  # fmt: skip
