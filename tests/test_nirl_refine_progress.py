"""MAP refinement after policy iteration (agents/nirl/refine_progress.py) on a set with known injected
noise: the relabel rate of injected actions and the keep rate of clean steps, both checked."""

import torch

from agents.nirl.losses import KEEP, RELABEL, refine_steps
from agents.nirl.refine_progress import ProgressRefine, progress_posterior, refined_to_go

N, A, NOISE = 2000, 5, 0.3


def noisy_steps(seed: int = 0):
    """Expert actions, recorded ones (30% random), a prior policy wrong on 10% of states, and each step's
    progress: about 0 for the expert's steps, about -1.5 for a random action that is not the expert's."""
    g = torch.Generator().manual_seed(seed)
    expert = torch.randint(A, (N,), generator=g)
    random = torch.randint(A, (N,), generator=g)
    injected = torch.rand(N, generator=g) < NOISE
    recorded = torch.where(injected, random, expert)
    favourite = torch.where(torch.rand(N, generator=g) < 0.1, (expert + 1) % A, expert)  # the prior's guess
    q = torch.full((N, A), -0.5)
    q[torch.arange(N), favourite] = 0.0
    wrong = recorded != expert
    progress = torch.where(wrong, -1.5 + 0.3 * torch.randn(N, generator=g), 0.1 * torch.randn(N, generator=g))
    return q, recorded, expert, progress, wrong


def rates(labels, recorded, expert, wrong):
    relabelled = float((labels[wrong] == expert[wrong]).float().mean())
    kept = float((labels[~wrong] == recorded[~wrong]).float().mean())
    return relabelled, kept


def refine(settings: ProgressRefine, seed: int = 0):
    q, recorded, expert, progress, wrong = noisy_steps(seed)
    posterior = progress_posterior(q, recorded, progress, NOISE, settings)
    assert torch.allclose(posterior.sum(dim=1), torch.ones(N))
    refined = refine_steps(posterior, recorded, settings.threshold)
    return rates(refined.labels, recorded, expert, wrong)


def test_progress_evidence_relabels_injected_noise_and_keeps_clean_steps():
    for seed in range(3):
        relabelled, kept = refine(ProgressRefine(temperature=0.1, offset=-0.5, scale=0.25), seed)
        assert relabelled >= 0.8 and kept >= 0.99, (seed, relabelled, kept)


def test_without_the_progress_evidence_a_wrong_prior_changes_clean_steps():
    _, kept = refine(ProgressRefine(temperature=0.1, scale=0.0))
    assert kept < 0.95  # the prior alone overrules clean steps where it is wrong (10% of states)


def test_refined_steps_to_go_leave_the_relabelled_steps_out():
    episodes = torch.tensor([0, 0, 0, 0, 1, 1])
    to_go = torch.tensor([4, 3, 2, 1, 0, 0])
    decisions = torch.tensor([KEEP, RELABEL, KEEP, KEEP, KEEP, KEEP])
    assert refined_to_go(episodes, to_go, decisions).tolist() == [3, 2, 2, 1, 0, 0]
