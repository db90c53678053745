"""The actor's watch on the learner's silence: batches held but nothing acknowledged for a while.

The outbox waits for acknowledgements without a word (that is its job); this thread
says so when none came for ``after`` seconds while batches were held, names the run
and the endpoint, and the likely cause, found from the learners' liveliness tokens:
no learner at all, learners only on other runs (a wrong ``--run``), or a learner on
this run that acknowledges nothing (an ACL denying this actor's puts or the learner's
acknowledgements, or a learner far behind). Repeats with back-off until an
acknowledgement arrives.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from services.common.waiting import WaitLog
from services.ops.status import learner_runs, no_learner_hint

log = logging.getLogger("navlearn.actor")


def silence_cause(run: str, learners: list[str]) -> str:
    """The likely cause of a silent learner, from the runs where learners hold liveliness tokens."""
    if run in learners:
        return (
            f"a learner is alive on run {run!r} but acknowledges nothing: the router's ACL may deny this "
            "actor's transitions or the learner's acknowledgements (check --credentials and the ACL), "
            f"or the learner is far behind (navlearn status --run {run})"
        )
    return no_learner_hint(run, learners)


class SilenceWatch:
    """A daemon thread warning while ``held()`` batches wait and no acknowledgement came for ``after`` s."""

    def __init__(
        self,
        session,
        run: str,
        where: str,
        held: Callable[[], int],
        after: float,
        poll: float = 0.5,
    ) -> None:
        self.session, self.run, self.held, self.after, self.poll = session, run, held, after, poll
        self.last_ack = time.monotonic()
        self.warnings = 0
        self._log = WaitLog(
            log,
            "no acknowledgement from the learner on run %r via %s while %d batches wait; %s (%.0f s so far)",
            run,
            where,
            first=after,
            level=logging.WARNING,
            gaps=(after, 2 * after, 4 * after, 8 * after),
        )
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="silence-watch", daemon=True)

    def acknowledged(self) -> None:
        """An acknowledgement arrived (called from the ack callback)."""
        self.last_ack = time.monotonic()

    def start(self) -> SilenceWatch:
        if self.after > 0:
            self._thread.start()
        return self

    def _watch(self) -> None:
        while not self._stop.wait(self.poll):
            held = self.held()
            if not held:
                self._log.reset()  # nothing waits: the silence counts from when something does
            elif self.last_ack > self._log.start:
                self._log.reset(self.last_ack)
            if held and self._log.due():
                self._log.tick(held, silence_cause(self.run, learner_runs(self.session, timeout=1.0)))
                self.warnings += 1

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)

    def __enter__(self) -> SilenceWatch:
        return self.start()

    def __exit__(self, *_exc: object) -> None:
        self.close()
