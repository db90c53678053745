"""A TorchRL replay buffer on disk without pickle: safetensors for the arrays, JSON for the rest.

TorchRL's own ``dumps``/``loads`` write ``prefetch.pkl`` and read it back with
``pickle.load``, and its storage loader follows ``meta.json`` files that may name
pickled leaves: whoever can write a checkpoint directory could run code in the
learner. This format holds the same state and is read without unpickling
anything:

    replay.json           {"format": "navlearn-replay/1", "len": n, "capacity": c,
                           "writer": {"_cursor", "_write_count"}, "batch_size", "rng_device"}
    replay.safetensors    "storage/<key>" the n stored rows of every field ("next/reward", ...),
                          "rng" the buffer's generator state (uint8)
    sampler/              prioritized buffers only: TorchRL's PrioritizedSampler.dumps
                          (sampler_metadata.json + two float64 arrays; nothing pickled)

Loading checks the format, the capacity and that every field holds ``len`` rows, so a
zeroed or truncated file fails with a ``ReplayFormatError`` naming it (safetensors checks its
own header against the file size); the learner's checkpoint manifest checks every byte
before this runs. A directory in TorchRL's own format (navlearn before 2026-12-01) is
refused with a message saying so, since reading it means unpickling.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file
from tensordict import TensorDict
from torchrl.data import TensorDictReplayBuffer

FORMAT = "navlearn-replay/1"
META_FILE = "replay.json"
ARRAYS_FILE = "replay.safetensors"
SAMPLER_DIR = "sampler"
_STORAGE = "storage/"


class ReplayFormatError(ValueError):
    """A replay directory that is not (or no longer) a readable navlearn replay."""


def save_replay(replay: TensorDictReplayBuffer, path: str | Path) -> None:
    """Write ``replay`` (storage rows, writer position, sampler, generator) into directory ``path``."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    state = replay.state_dict()  # references to the live tensors: nothing copied here
    n = len(replay)
    tensors: dict[str, torch.Tensor] = {}
    if n:
        rows = replay.storage[:n]
        tensors.update({_STORAGE + k: v.contiguous() for k, v in rows.flatten_keys("/").items()})
    rng = state.get("_rng")
    if rng is not None:
        tensors["rng"] = rng[0].contiguous()
    save_file(tensors, str(path / ARRAYS_FILE))
    if state.get("_sampler"):  # a prioritized sampler's sum and min trees
        replay.sampler.dumps(path / SAMPLER_DIR)
    meta = {
        "format": FORMAT,
        "len": n,
        "capacity": int(replay.storage.max_size),
        "writer": {k: int(v) for k, v in state["_writer"].items()},
        "batch_size": state["_batch_size"],
        "rng_device": None if rng is None else str(rng[1]),
    }
    (path / META_FILE).write_text(json.dumps(meta, indent=1) + "\n")


def load_replay(replay: TensorDictReplayBuffer, path: str | Path) -> None:
    """Fill the empty ``replay`` from directory ``path`` (written by ``save_replay``)."""
    path = Path(path)
    meta = _read_meta(path)
    capacity = int(replay.storage.max_size)
    if meta["capacity"] != capacity:
        raise ReplayFormatError(
            f"{path}: saved with replay capacity {meta['capacity']}, this buffer holds {capacity}; "
            f"set --replay-capacity {meta['capacity']} to resume it"
        )
    try:
        tensors = load_file(str(path / ARRAYS_FILE))
    except (OSError, SafetensorError) as exc:
        raise ReplayFormatError(f"{path / ARRAYS_FILE}: unreadable ({exc})") from None
    n = int(meta["len"])
    rows = {k.removeprefix(_STORAGE): v for k, v in tensors.items() if k.startswith(_STORAGE)}
    bad = {k: tuple(v.shape) for k, v in rows.items() if v.ndim == 0 or v.shape[0] != n}
    if bad or (n and not rows) or n > capacity:
        raise ReplayFormatError(f"{path / ARRAYS_FILE}: replay.json says {n} rows, the arrays hold {bad}")
    if n:
        replay.storage.set(torch.arange(n), TensorDict(rows, batch_size=[n]).unflatten_keys("/"))
    replay.writer.load_state_dict(meta["writer"])
    if (path / SAMPLER_DIR).is_dir():
        replay.sampler.loads(path / SAMPLER_DIR)
    if "rng" in tensors and meta.get("rng_device"):
        generator = torch.Generator(device=meta["rng_device"])
        generator.set_state(tensors["rng"])
        replay.set_rng(generator)


def _read_meta(path: Path) -> dict:
    if (path / "buffer_metadata.json").exists() and not (path / META_FILE).exists():
        raise ReplayFormatError(
            f"{path}: a replay written by TorchRL's dumps (navlearn before 2026-12-01), whose loader "
            "unpickles prefetch.pkl; navlearn no longer reads it. Move the checkpoint away to start "
            "afresh, or resume it once with the navlearn that wrote it"
        )
    try:
        meta = json.loads((path / META_FILE).read_text())
    except (OSError, ValueError) as exc:
        raise ReplayFormatError(f"{path / META_FILE}: unreadable ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ReplayFormatError(f"{path / META_FILE}: not a {FORMAT} replay")
    for key, kind in (("len", int), ("capacity", int), ("writer", dict)):
        if not isinstance(meta.get(key), kind):
            raise ReplayFormatError(f"{path / META_FILE}: field {key!r} missing or not {kind.__name__}")
    return meta


def stored_bytes(replay: TensorDictReplayBuffer) -> int:
    """About what ``save_replay`` writes for ``replay``: its stored rows (plus a prioritized
    sampler's two float64 trees), for a free-space check before a checkpoint."""
    n = len(replay)
    rows = int(replay.storage[:n].bytes()) if n else 0
    trees = 16 * int(replay.storage.max_size) if replay.state_dict().get("_sampler") else 0
    return rows + trees
