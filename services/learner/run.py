"""The learner process: locks its checkpoint directory (one writer per run), builds the NNQL
learner, its buffers and inbox, opens the Zenoh session
(hosting the router unless told to connect), resumes from the newest intact checkpoint, replays
the write-ahead log, then runs services.learner.service.LearnerService until ``stop``."""

from __future__ import annotations

import contextlib
import logging
import threading
import time

from agents.nirl.config import NIRLConfig
from agents.nnql.config import NNQLConfig
from agents.nnql.learner import NNQLLearner
from protocols.limits import Limits
from services.common.dirlock import DirLock
from services.common.transport import ZenohSettings, declare_alive, open_session
from services.learner.config import LearnerConfig
from services.learner.demo_buffer import DemoBuffer
from services.learner.inbox import learner_inbox
from services.learner.nirl import NIRLTrainer
from services.learner.service import LearnerService
from services.ops.router import exposure_warning
from worlds.config import OBSERVATIONS, observation_settings
from worlds.env import observation_space
from worlds.own_env import EnvConfig, EnvSpaces, describe_env, image_hwc

log = logging.getLogger("navlearn.learner")


def run_learner(
    config: LearnerConfig,
    nnql: NNQLConfig,
    settings: ZenohSettings,
    stop: threading.Event,
    nirl: NIRLConfig | None = None,
    env: EnvConfig | None = None,
    spaces: EnvSpaces | None = None,
) -> int:
    """Process set-up around the learner loop; returns the exit code. ``nirl`` configures NIRL
    when ``config.nirl`` is on (its defaults otherwise); ``env``: a Gymnasium env the actors run
    instead of navlearn's world (its spaces size the networks and the wire's limits; ``spaces``: those
    already read by the caller's checks, else one copy of the env is built to read them).
    A checkpoint directory another live learner holds is refused
    (services.common.dirlock.DirectoryInUse, a ValueError) before anything in it is read or written."""
    with contextlib.ExitStack() as held:
        if config.checkpoint_dir:
            held.enter_context(learner_lock(config.checkpoint_dir))
        return _run_learner(config, nnql, settings, stop, nirl, env or EnvConfig(), spaces)


def learner_lock(checkpoint_dir: str) -> DirLock:
    """The lock a learner holds on its checkpoint directory (checkpoints and write-ahead log)."""
    return DirLock(
        checkpoint_dir,
        LOCK_NAME,
        "checkpoint directory",
        "give this learner another --checkpoint-dir (with `navlearn up`: another --run or --out)",
    )


LOCK_NAME = "learner.lock"
"""the file in the checkpoint directory whose OS lock the learner holds for its lifetime"""


def _run_learner(
    config: LearnerConfig,
    nnql: NNQLConfig,
    settings: ZenohSettings,
    stop: threading.Event,
    nirl: NIRLConfig | None,
    env: EnvConfig,
    spaces: EnvSpaces | None,
) -> int:
    nav = OBSERVATIONS[config.observation]  # what the actors observe
    image = None  # navlearn's world observes no image
    if env.own_world:
        obs_dim, n_actions = int(observation_space(nav).shape[0]), nav.robot.n_actions
        observation = observation_settings(nav)
    else:
        if config.nirl:
            raise ValueError(
                f"--nirl learns from navlearn's world and its expert; with --env {env.env} train NNQL only "
                "(drop --nirl)"
            )
        # the env's own spaces, flattened, and the image its observation is, if one
        obs_dim, n_actions, image = spaces or describe_env(env)
        observation = None  # no navlearn observation settings: the env record says what it is
    learner = NNQLLearner(
        nnql, obs_dim, n_actions, device=config.device, replay_dir=config.replay_dir, observation=observation,
        image=image,
    )  # fmt: skip
    if not env.own_world:
        log.info(
            "learner: env %s, %d inputs%s, %d actions, network %s",
            env.signature(),
            obs_dim,
            "" if image is None else " (image {}x{}x{})".format(*image_hwc(image)),
            n_actions,
            learner.config.network,
        )
    learner.env = env.record()
    demos = DemoBuffer(config.demo_capacity, obs_dim, seed=nnql.seed)
    limits = Limits(n_actions=n_actions, max_obs_dim=obs_dim)
    inbox = learner_inbox(config, nnql, limits, settings.run, (config.acl_names, settings.acl_file))
    if settings.mode == "router" and (warning := exposure_warning(settings)):
        log.warning("%s", warning)  # the learner hosts the router
    session = open_session(settings, stop=stop)
    if session is None:
        return 0
    sender = f"{config.id}#{int(time.time())}"
    trainer = None
    if config.nirl:
        trainer = NIRLTrainer(
            nirl or NIRLConfig(seed=nnql.seed),
            nav,
            learner.replay,
            demos.replay,
            session,
            settings.run,
            sender,
            config.broadcast_every,
            device=config.device,
        )
    # The session closes last, even if closing the service fails: a held session keeps the
    # process alive.
    with (
        session,
        LearnerService(
            config, learner, session, settings.run, inbox, demos, sender, trainer, env.signature()
        ) as service,
    ):
        latest = service.checkpoints.newest_intact() if config.resume and service.checkpoints else None
        if latest is not None:
            service.resume(latest)
        service.replay_log()
        with contextlib.ExitStack() as declared:
            for subscriber in inbox.subscribe(session):
                declared.enter_context(subscriber)
            declared.enter_context(declare_alive(session, settings.run, "learner", config.id))
            log.info(
                "learner %s up (%s mode), run %s, version %d",
                config.id,
                settings.mode,
                settings.run,
                learner.version,
            )
            code = service.run(stop)
    log.info("learner stopped")
    return code
