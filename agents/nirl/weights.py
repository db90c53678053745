"""Network weights at every NIRL iteration, and the plot of how they change (thesis ch. 5's
analysis of the weight changes).

``WeightHistory.record`` keeps a copy of the reward and policy (Q) networks' weights per
iteration; ``save``/``load`` write them as one safetensors file, each parameter stacked
along a leading iteration axis (``reward/0.weight`` -> (K, out, in)), with the iteration
numbers under ``iterations``. ``plot_weight_changes`` draws, per network and layer, the
relative step ``|W_k - W_{k-1}| / |W_{k-1}|`` and the drift ``|W_k - W_0| / |W_0|``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

HISTORY_FILE = "weights_history.safetensors"
NETWORKS = ("reward", "policy")


class WeightHistory:
    """Per-iteration copies of named weight arrays of several networks."""

    def __init__(self) -> None:
        self.iterations: list[int] = []
        self.snapshots: dict[str, list[np.ndarray]] = {}

    def __len__(self) -> int:
        return len(self.iterations)

    def record(self, iteration: int, **networks: dict[str, np.ndarray]) -> None:
        """Store ``networks`` (e.g. ``reward=..., policy=...``: name -> array) for ``iteration``."""
        names = {f"{net}/{name}" for net, weights in networks.items() for name in weights}
        if self.snapshots and names != set(self.snapshots):
            raise ValueError("every record must hold the same parameters")
        for net, weights in networks.items():
            for name, value in weights.items():
                self.snapshots.setdefault(f"{net}/{name}", []).append(np.array(value, dtype=np.float32))
        self.iterations.append(int(iteration))

    def stacked(self) -> dict[str, np.ndarray]:
        out = {name: np.stack(values) for name, values in self.snapshots.items()}
        out["iterations"] = np.asarray(self.iterations, dtype=np.int64)
        return out

    def save(self, path: str | Path) -> Path:
        from safetensors.numpy import save_file

        path = Path(path)
        save_file(self.stacked(), str(path))
        return path

    @classmethod
    def load(cls, path: str | Path) -> WeightHistory:
        from safetensors.numpy import load_file

        data = load_file(str(path))
        if "iterations" not in data:
            raise ValueError(f"{path}: not a NIRL weight history (no 'iterations')")
        history = cls()
        history.iterations = [int(i) for i in data.pop("iterations")]
        history.snapshots = {name: list(stack) for name, stack in data.items()}
        return history

    def averaged(self, network: str, last: int) -> dict[str, np.ndarray]:
        """``network``'s weights averaged over the last ``last`` records (stochastic weight averaging
        along the rounds, Izmailov et al. 2018), name -> array as ``record`` took them."""
        if not 1 <= last <= len(self):
            raise ValueError(f"averaged: last={last} outside the {len(self)} recorded iterations")
        prefix = network + "/"
        return {name.removeprefix(prefix): np.mean(stack[-last:], axis=0, dtype=np.float64).astype(np.float32)
                for name, stack in self.snapshots.items() if name.startswith(prefix)}  # fmt: skip

    def layer_changes(self, network: str) -> dict[str, dict[str, np.ndarray]]:
        """Per weight matrix of ``network``: relative ``step`` and ``drift`` per iteration (K,)."""
        out = {}
        for name, stack in self.snapshots.items():
            net, _, param = name.partition("/")
            if net != network or not param.endswith("weight"):
                continue
            w = np.stack(stack).reshape(len(stack), -1).astype(np.float64)
            norms = np.linalg.norm(w, axis=1)
            step = np.zeros(len(w))
            step[1:] = np.linalg.norm(np.diff(w, axis=0), axis=1) / np.maximum(norms[:-1], 1e-12)
            drift = np.linalg.norm(w - w[0], axis=1) / max(norms[0], 1e-12)
            out[param] = {"step": step, "drift": drift}
        return out


def plot_weight_changes(history: WeightHistory, out: str | Path, title: str = "NIRL weight changes") -> Path:
    """Write a PNG with one row per network: relative step and drift of each layer's weights."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if len(history) < 2:
        raise ValueError("need weights from at least two iterations to plot their change")
    iterations = np.asarray(history.iterations)
    networks = [n for n in NETWORKS if history.layer_changes(n)]
    fig, axes = plt.subplots(len(networks), 2, figsize=(10, 3.2 * len(networks)), squeeze=False)
    for row, network in enumerate(networks):
        changes = history.layer_changes(network)
        for param, values in sorted(changes.items(), key=lambda kv: int(kv[0].split(".")[-2] or 0)):
            label = f"layer {param.removesuffix('.weight')}"
            axes[row, 0].plot(iterations[1:], values["step"][1:], label=label)
            axes[row, 1].plot(iterations, values["drift"], label=label)
        steps = np.concatenate([values["step"][1:] for values in changes.values()])
        log_scale = bool(len(steps)) and bool((steps > 0).all())  # a layer that did not move has no log
        axes[row, 0].set(
            ylabel=f"{network}\n|W_k - W_k-1| / |W_k-1|", yscale="log" if log_scale else "linear"
        )
        axes[row, 1].set(ylabel="|W_k - W_0| / |W_0|")
        for ax in axes[row]:
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("iteration")
    fig.suptitle(title)
    fig.tight_layout()
    out = Path(out)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
