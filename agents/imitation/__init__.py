"""Policy learning from multiple demonstrations (thesis ch. 3): behaviour cloning of the
modified-A* expert with an MLP trained by back-propagation.

``agents.imitation.config.ImitationConfig`` holds the knobs (no torch import);
``agents.imitation.train`` extracts the dataset, trains (``train_policy``) and saves
(``save_trained``) in the shared policy format of ``agents.evaluation.policies``.
"""
