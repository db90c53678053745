"""Waiting out loud: a process that waits says what for and where at once, then again with back-off."""

from __future__ import annotations

import logging
import time

GAPS = (2.0, 4.0, 8.0, 16.0, 30.0)
"""seconds between two reminders: 2, 4, 8, 16, then every 30"""


class WaitLog:
    """Logs ``message % (*args, seconds waited)`` when due: after ``first`` s, then after each gap.

    ``due()`` is cheap, so a loop calls ``tick()`` every round; ``reset()`` starts over (the awaited
    thing came, or came back).
    """

    def __init__(
        self,
        logger: logging.Logger,
        message: str,
        *args: object,
        first: float = 0.0,
        level: int = logging.INFO,
        gaps: tuple[float, ...] = GAPS,
    ) -> None:
        self.logger, self.message, self.args, self.level = logger, message, args, level
        self.first, self.gaps = first, gaps
        self.reset()

    def reset(self, start: float | None = None) -> None:
        """Start over, counting the wait from ``start`` (a ``time.monotonic()``; default now)."""
        self.start = time.monotonic() if start is None else start
        self.next = self.start + self.first
        self.said = 0

    @property
    def waited(self) -> float:
        return time.monotonic() - self.start

    def due(self) -> bool:
        return time.monotonic() >= self.next

    def tick(self, *extra: object) -> bool:
        """Log once if due (``extra`` after the constructor's args, then the seconds waited)."""
        if not self.due():
            return False
        self.logger.log(self.level, self.message, *self.args, *extra, self.waited)
        self.next = time.monotonic() + self.gaps[min(self.said, len(self.gaps) - 1)]
        self.said += 1
        return True
