"""The compiled step of the navigation world: one call moves every robot, checks its
motion for collisions, moves its discs, casts its beams, scores the step and (for the
vector env) resets finished robots. The single env calls the same functions with one
robot, so both envs are the same program.

Arrays are grouped in tuples (see :mod:`worlds.batch` for who builds them):
``maps``, ``entries`` (from :class:`worlds.bank.MapBank`), ``robots`` (per-robot state, incl.
its random stream and the range of pool entries it draws episodes from),
``discs`` (per-robot moving discs), ``finals`` (terminal results of auto-reset robots).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worlds.config import NavConfig
from worlds.obstacles import move_disc, place_discs, swept_contact
from worlds.outcomes import Outcome
from worlds.rng import gauss, randint, uniform
from worlds.robot import capsule_hits_grid
from worlds.sensors import cast_ray, ray_disc

# indices into the float64 parameter vector built by make_params
P_STEP, P_RADIUS, P_TNOISE, P_RNOISE, P_HEADINGS, P_MAXR, P_SNOISE = range(7)
P_DROP, P_RGOAL, P_RCOLL, P_RSTEP, P_RPROG, P_MAXSTEPS, P_GOALTOL = range(7, 14)
P_OCOUNT, P_ORAD, P_OSPEED, P_OPATROL, P_OLENGTH, P_OSPAWN = range(14, 20)
# indices into the robots tuple built by worlds.batch.NavBatch
R_X, R_Y, R_TH, R_GX, R_GY, R_STEPS, R_PLEN, R_PDIST = range(8)
R_ENT, R_SCELL, R_GCELL, R_OUTCOME, R_RNG, R_PLO, R_PN = range(8, 15)

RUNNING, GOAL = int(Outcome.RUNNING), int(Outcome.GOAL)
HIT_STATIC, HIT_DYNAMIC, TIMEOUT = (
    int(Outcome.COLLISION_STATIC),
    int(Outcome.COLLISION_DYNAMIC),
    int(Outcome.TIMEOUT),
)


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
    return np.asarray(values, dtype=np.float64)


@njit(cache=True)
def observe(i, maps, entries, robots, discs, params, beam_c, beam_s, obs):
    """Write robot ``i``'s observation: ranges / max_range, squashed goal distance, sin and cos
    of the goal bearing relative to the heading."""
    blocked, gap, moff, mh, mw, mcell = maps
    x, y, th, gx, gy, rng = robots[R_X], robots[R_Y], robots[R_TH], robots[R_GX], robots[R_GY], robots[R_RNG]
    ox, oy, orad, ocount = discs[0], discs[1], discs[4], discs[10]
    m = entries[0][robots[R_ENT][i]]
    max_range = params[P_MAXR]
    noise, drop = params[P_SNOISE], params[P_DROP]
    c, s = math.cos(th[i]), math.sin(th[i])
    n_beams = beam_c.shape[0]
    for k in range(n_beams):
        dx = c * beam_c[k] - s * beam_s[k]
        dy = s * beam_c[k] + c * beam_s[k]
        d = cast_ray(blocked, moff[m], mh[m], mw[m], mcell[m], gap, x[i], y[i], dx, dy, max_range)
        for j in range(ocount[i]):
            d = min(d, ray_disc(x[i], y[i], dx, dy, ox[i, j], oy[i, j], orad[i, j]))
        if noise > 0.0:
            d = min(max(d + noise * gauss(rng, i), 0.0), max_range)
        if drop > 0.0 and uniform(rng, i) < drop:
            d = max_range
        obs[i, k] = d / max_range
    ux, uy = gx[i] - x[i], gy[i] - y[i]
    dist = math.hypot(ux, uy)
    obs[i, n_beams] = dist / (dist + max_range)
    if dist > 0.0:
        obs[i, n_beams + 1] = (-ux * s + uy * c) / dist
        obs[i, n_beams + 2] = (ux * c + uy * s) / dist
    else:
        obs[i, n_beams + 1] = 0.0
        obs[i, n_beams + 2] = 1.0


@njit(cache=True)
def reset_robot(i, forced, keep_discs, maps, entries, robots, discs, params, beam_c, beam_s, obs):
    """Start a new episode for robot ``i``: entry ``forced`` (or a random pool entry when
    negative, with fresh random endpoints if the entry allows), random initial heading,
    new discs unless ``keep_discs``; then observe."""
    blocked, gap, moff, mh, mw, mcell = maps
    emap, estart, egoal, ecoff, ecn, emind, eres, cand = entries
    x, y, th, gx, gy, rng = robots[R_X], robots[R_Y], robots[R_TH], robots[R_GX], robots[R_GY], robots[R_RNG]
    ent, scell, gcell, plo, pn = robots[R_ENT], robots[R_SCELL], robots[R_GCELL], robots[R_PLO], robots[R_PN]
    ox, oy, ovx, ovy, orad, opat, oax, oay, obx, oby, ocount = discs
    j = forced if forced >= 0 else plo[i] + randint(rng, i, pn[i])
    ent[i] = j
    m = emap[j]
    width, cell = mw[m], mcell[m]
    sr, sc, gr, gc = estart[j, 0], estart[j, 1], egoal[j, 0], egoal[j, 1]
    if forced < 0 and eres[j]:
        s_idx = cand[ecoff[j] + randint(rng, i, ecn[j])]
        for _ in range(32):
            g_idx = cand[ecoff[j] + randint(rng, i, ecn[j])]
            if math.hypot(s_idx // width - g_idx // width, s_idx % width - g_idx % width) * cell >= emind[j]:
                sr, sc, gr, gc = s_idx // width, s_idx % width, g_idx // width, g_idx % width
                break
    scell[i, 0], scell[i, 1], gcell[i, 0], gcell[i, 1] = sr, sc, gr, gc
    x[i], y[i] = (sc + 0.5) * cell, (sr + 0.5) * cell
    gx[i], gy[i] = (gc + 0.5) * cell, (gr + 0.5) * cell
    choices = int(params[P_HEADINGS])
    if choices > 0:
        heading = randint(rng, i, choices) * (2.0 * math.pi / choices)
    else:
        heading = 2.0 * math.pi * uniform(rng, i)
    th[i] = (heading + math.pi) % (2.0 * math.pi) - math.pi
    robots[R_STEPS][i] = 0
    robots[R_PLEN][i] = 0.0
    robots[R_PDIST][i] = math.hypot(gx[i] - x[i], gy[i] - y[i])
    robots[R_OUTCOME][i] = RUNNING
    if not keep_discs:
        count = min(int(params[P_OCOUNT]), ox.shape[1])
        patrol = params[P_OPATROL] > 0.0
        ocount[i] = place_discs(
            i, rng, blocked, moff[m], mh[m], width, cell, gap, cand, ecoff[j], ecn[j], x[i], y[i],
            params[P_RADIUS], count, params[P_ORAD], params[P_OSPEED], patrol, params[P_OLENGTH],
            params[P_OSPAWN], ox, oy, ovx, ovy, orad, opat, oax, oay, obx, oby,
        )  # fmt: skip
    observe(i, maps, entries, robots, discs, params, beam_c, beam_s, obs)


@njit(cache=True)
def step_robot(i, action, maps, entries, robots, discs, params, turns) -> float:
    """Move robot ``i`` and its discs one step; set its outcome; return its reward."""
    blocked, gap, moff, mh, mw, mcell = maps
    x, y, th, gx, gy, rng = robots[R_X], robots[R_Y], robots[R_TH], robots[R_GX], robots[R_GY], robots[R_RNG]
    steps, plen, pdist, outcome = robots[R_STEPS], robots[R_PLEN], robots[R_PDIST], robots[R_OUTCOME]
    ox, oy, ovx, ovy, orad, opat, oax, oay, obx, oby, ocount = discs
    m = entries[0][robots[R_ENT][i]]
    off, height, width, cell = moff[m], mh[m], mw[m], mcell[m]
    radius = params[P_RADIUS]
    heading = th[i] + turns[action]
    if params[P_RNOISE] > 0.0:
        heading += params[P_RNOISE] * gauss(rng, i)
    distance = params[P_STEP]
    if params[P_TNOISE] > 0.0:
        distance = max(distance + params[P_TNOISE] * gauss(rng, i), 0.0)
    heading = (heading + math.pi) % (2.0 * math.pi) - math.pi
    th[i] = heading
    x0, y0 = x[i], y[i]
    x1, y1 = x0 + distance * math.cos(heading), y0 + distance * math.sin(heading)
    result = RUNNING
    if capsule_hits_grid(blocked, off, height, width, cell, gap, x0, y0, x1, y1, radius):
        result = HIT_STATIC
    for k in range(ocount[i]):
        px, py = ox[i, k], oy[i, k]
        ox[i, k], oy[i, k], ovx[i, k], ovy[i, k] = move_disc(
            blocked, off, height, width, cell, gap, px, py, ovx[i, k], ovy[i, k], orad[i, k], opat[i, k],
            oax[i, k], oay[i, k], obx[i, k], oby[i, k],
        )  # fmt: skip
        if result == RUNNING and swept_contact(
            x0, y0, x1, y1, px, py, ox[i, k], oy[i, k], radius + orad[i, k]
        ):
            result = HIT_DYNAMIC
    reward = params[P_RSTEP]
    if result == RUNNING:
        x[i], y[i] = x1, y1
        plen[i] += distance
        dist = math.hypot(gx[i] - x1, gy[i] - y1)
        reward += params[P_RPROG] * (pdist[i] - dist)
        pdist[i] = dist
        if dist <= params[P_GOALTOL]:
            result = GOAL
            reward += params[P_RGOAL]
    else:
        reward += params[P_RCOLL]
    steps[i] += 1
    if result == RUNNING and steps[i] >= params[P_MAXSTEPS]:
        result = TIMEOUT
    outcome[i] = result
    return reward


@njit(cache=True)
def step_all(
    actions, autoreset, maps, entries, robots, discs, params, turns, beam_c, beam_s, obs, reward, terminated,
    truncated, finals,
):  # fmt: skip
    """Step every robot; with ``autoreset``, a finished robot's terminal observation and results
    go to ``finals`` and it starts its next episode in the same call. Returns the number done."""
    x, y, th, steps, plen = robots[R_X], robots[R_Y], robots[R_TH], robots[R_STEPS], robots[R_PLEN]
    ent, scell, gcell, outcome = robots[R_ENT], robots[R_SCELL], robots[R_GCELL], robots[R_OUTCOME]
    f_obs, f_outcome, f_plen, f_steps, f_pose, f_ent, f_scell, f_gcell, f_done = finals
    n_done = 0
    for i in range(actions.shape[0]):
        reward[i] = step_robot(i, actions[i], maps, entries, robots, discs, params, turns)
        observe(i, maps, entries, robots, discs, params, beam_c, beam_s, obs)
        result = outcome[i]
        terminated[i] = result in (GOAL, HIT_STATIC, HIT_DYNAMIC)
        truncated[i] = result == TIMEOUT
        done = result != RUNNING
        f_done[i] = done
        if done:
            n_done += 1
            if autoreset:
                f_obs[i, :] = obs[i, :]
                f_outcome[i], f_plen[i], f_steps[i] = result, plen[i], steps[i]
                f_pose[i, 0], f_pose[i, 1], f_pose[i, 2] = x[i], y[i], th[i]
                f_ent[i] = ent[i]
                f_scell[i, 0], f_scell[i, 1] = scell[i, 0], scell[i, 1]
                f_gcell[i, 0], f_gcell[i, 1] = gcell[i, 0], gcell[i, 1]
                reset_robot(i, -1, False, maps, entries, robots, discs, params, beam_c, beam_s, obs)
    return n_done


@njit(cache=True)
def reset_some(indices, forced, keep_discs, maps, entries, robots, discs, params, beam_c, beam_s, obs):
    for n in range(indices.shape[0]):
        reset_robot(
            indices[n], forced[n], keep_discs[n], maps, entries, robots, discs, params, beam_c, beam_s, obs
        )
