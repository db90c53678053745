"""Terminal teleoperation for the human demonstrator: drive the robot with the arrow keys.

The map, the robot (an arrow showing its heading), its range beams (``*`` where each
beam ends), its trail and the goal are drawn with curses, two characters per cell.
Keys (the robot's five actions turn it, then drive it one step forward):

====================  ======================  =======
key                   action                  turn
====================  ======================  =======
Up, w, k, 3           straight on             0
Left, a, h, 2         half left               -45 deg
Right, d, l, 4        half right              +45 deg
q, 1                  hard left               -90 deg
e, 5                  hard right              +90 deg
x                     quit
====================  ======================  =======

("left" turns towards the robot's left as drawn: rows grow downwards, so headings
grow clockwise on the screen.) Each finished episode that reaches the goal (any
episode with ``keep_failures``) is published as a DemoBatch with source ``human``;
the next one starts right away. Log lines are held back while curses owns the screen.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from typing import Protocol

import numpy as np

from agents.demos import Demo, make_demo
from services.demonstrator.config import DemonstratorConfig
from services.demonstrator.episodes import nav_config
from worlds.env import NavigationEnv
from worlds.outcomes import OUTCOME_NAMES, Outcome


class DemoSink(Protocol):
    """Where finished episodes go (services.demonstrator.demonstrator.DemoPublisher)."""

    episodes: int
    """episodes published so far"""

    def publish(self, demos: list[Demo]) -> bool: ...


log = logging.getLogger("navlearn.teleop")
HEADING_GLYPHS = (">", "\\", "v", "/", "<", "\\", "^", "/")
"""robot glyph per heading octant, starting at +x (east) and turning clockwise on screen"""
QUIT_KEYS = (ord("x"), ord("X"))


def key_actions() -> dict[int, int]:
    """Curses key code -> action index (for the default 5-action robot)."""
    import curses

    table = {
        2: (curses.KEY_UP, "w", "k", "3"),
        1: (curses.KEY_LEFT, "a", "h", "2"),
        3: (curses.KEY_RIGHT, "d", "l", "4"),
        0: ("q", "1"),
        4: ("e", "5"),
    }
    return {(ord(k) if isinstance(k, str) else k): action for action, ks in table.items() for k in ks}


def heading_glyph(theta: float) -> str:
    octant = round((theta % (2 * math.pi)) / (math.pi / 4)) % 8
    return HEADING_GLYPHS[octant]


def render_frame(
    blocked: np.ndarray,
    cell_size: float,
    pose: tuple[float, float, float],
    goal: tuple[int, int],
    beam_ends: np.ndarray,
    trail: list[tuple[float, float]],
) -> list[str]:
    """The map as text rows, two characters per cell: ``##`` blocked, ``. `` free, ``o`` trail,
    ``*`` beam ends, ``G`` goal and the robot's heading glyph (drawn last, on top)."""
    h, w = blocked.shape
    cells = [["##" if blocked[r, c] else ". " for c in range(w)] for r in range(h)]

    def mark(x: float, y: float, text: str) -> None:
        r, c = int(y // cell_size), int(x // cell_size)
        if 0 <= r < h and 0 <= c < w:
            cells[r][c] = text

    for x, y in trail:
        mark(x, y, "o ")
    for x, y in beam_ends:
        mark(float(x), float(y), "* ")
    cells[goal[0]][goal[1]] = "G "
    mark(pose[0], pose[1], heading_glyph(pose[2]) + " ")
    return ["".join(row) for row in cells]


def beam_ends(obs: np.ndarray, pose, nav) -> np.ndarray:
    """(n_beams, 2) points where the robot's beams end, from its observation."""
    sensors = nav.sensors
    ranges = np.asarray(obs[: sensors.n_beams], dtype=np.float64) * sensors.max_range
    angles = pose[2] + sensors.beam_angles
    return np.column_stack([pose[0] + ranges * np.cos(angles), pose[1] + ranges * np.sin(angles)])


def drive(config: DemonstratorConfig, publisher: DemoSink, stop: threading.Event) -> None:
    """Run the teleoperation UI until quit, stop or ``config.episodes`` published episodes."""
    import curses

    root = logging.getLogger()
    level = root.level
    root.setLevel(logging.WARNING)  # log lines would tear the curses screen
    try:
        curses.wrapper(lambda screen: _session(screen, config, publisher, stop))
    finally:
        root.setLevel(level)


def _draw(screen, rows: list[str], status: list[str]) -> None:
    import curses

    screen.erase()
    height, width = screen.getmaxyx()
    for i, line in enumerate([*rows, "", *status]):
        if i >= height - 1:
            break
        with contextlib.suppress(curses.error):  # the bottom-right cell cannot be written
            screen.addstr(i, 0, line[: width - 1])
    screen.refresh()


def _session(screen, config: DemonstratorConfig, publisher: DemoSink, stop: threading.Event) -> None:
    import curses

    with contextlib.suppress(curses.error):  # terminals without cursor visibility control
        curses.curs_set(0)
    screen.keypad(True)
    screen.timeout(200)  # getch gives up after 200 ms so SIGTERM (stop) is noticed
    actions_of = key_actions()
    nav = nav_config(config)
    env = NavigationEnv(nav, maps=config.maps)
    last = "drive to G"
    index = 0
    while not stop.is_set() and not (config.episodes and publisher.episodes >= config.episodes):
        seed = config.seed + index
        obs, info = env.reset(seed=seed)
        task = info["task"]
        observations, poses = [obs], [info["pose"]]
        actions, rewards, terms, truncs = [], [], [], []
        done = False
        while not done:
            pose = info["pose"]
            rows = render_frame(
                task.grid.blocked,
                task.grid.cell_size,
                tuple(pose),
                task.goal,
                beam_ends(obs, pose, nav),
                [(p[0], p[1]) for p in poses[:-1]],
            )
            status = [
                f"episode {index + 1} (seed {seed})  step {len(actions)}/{nav.max_steps}  "
                f"published {publisher.episodes}  | {last}",
                "keys: Up/w straight  Left/a Right/d half turn  q/e hard turn  x quit",
            ]
            _draw(screen, rows, status)
            key = screen.getch()
            if stop.is_set():
                return
            if key in QUIT_KEYS:
                return
            if key not in actions_of:
                continue
            action = actions_of[key]
            obs, reward, terminated, truncated, info = env.step(action)
            observations.append(obs)
            poses.append(info["pose"])
            actions.append(action)
            rewards.append(reward)
            terms.append(terminated)
            truncs.append(truncated)
            done = terminated or truncated
        outcome = int(info["outcome"])
        last = f"episode {index + 1}: {OUTCOME_NAMES[outcome]} after {len(actions)} steps"
        if outcome == Outcome.GOAL or config.keep_failures:
            demo = make_demo(
                observations, actions, rewards, terms, truncs, poses, task, "human", seed, 0.0, outcome
            )
            _draw(screen, [], [last, "publishing (waiting for a learner if none is up) ..."])
            if publisher.publish([demo]):
                last += ", published"
        index += 1
