"""What every service process does the same way: logging, stop signals, scalars.

Kept apart from the service classes (Sample Factory's split): a service object
gets an open session (services.common.transport.open_session) and a stop event.
"""

from __future__ import annotations

import faulthandler
import logging
import os
import signal
import sys
import threading
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

log = logging.getLogger("navlearn.process")


def setup_logging(verbose: bool = False) -> None:
    """Log lines to stdout (what supervisord and systemd collect); quiet third-party loggers."""
    sys.stdout.reconfigure(line_buffering=True)  # a pipe or file otherwise holds lines back
    faulthandler.register(signal.SIGUSR1, all_threads=True)  # `kill -USR1 <pid>`: every thread's stack
    logging.basicConfig(
        stream=sys.stdout,
        level=logging.DEBUG if verbose else logging.INFO,
        format="%(asctime)s %(name)s %(levelname)s %(message)s",
        force=True,
    )
    os.environ.setdefault("RL_LOGGING_LEVEL", "WARNING")  # torchrl sets its level from it when imported
    for noisy in ("torchrl", "matplotlib", "PIL", "numba"):
        logging.getLogger(noisy).setLevel(logging.WARNING)
    # Decoded arrays are read-only views of the received bytes; torch warns when wrapping them,
    # but the replay buffer copies them on insert, so nothing ever writes through the view.
    warnings.filterwarnings("ignore", message="The given NumPy array is not writable")
    import zenoh

    zenoh.init_log_from_env_or("error")


def stop_on_signals(
    first: Callable[[], None] | None = None, event: threading.Event | None = None
) -> threading.Event:
    """An event set by SIGTERM or SIGINT (the main loop polls it and stops cleanly): ``event``, or a
    new one. ``first``, if given, runs in the handler before anything else (``navlearn drive`` sends
    zero velocity there)."""
    stop = threading.Event() if event is None else event

    def handler(signum: int, _frame: Any) -> None:
        if first is not None:
            first()
        if not stop.is_set():
            log.info("received %s, stopping", signal.Signals(signum).name)
        stop.set()

    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, handler)
    return stop


class Scalars:
    """TensorBoard scalars (``torch.utils.tensorboard``); does nothing without a directory."""

    def __init__(self, logdir: str | Path | None) -> None:
        self.writer = None
        if logdir:
            from torch.utils.tensorboard import SummaryWriter

            self.writer = SummaryWriter(str(logdir), flush_secs=10)

    def add(self, values: dict[str, float], step: int, wall_time: float | None = None) -> None:
        if self.writer is None:
            return
        for name, value in values.items():
            if value is not None:
                self.writer.add_scalar(name, float(value), global_step=int(step), walltime=wall_time)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
