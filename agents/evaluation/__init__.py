"""Shared evaluation (DESIGN.md "Evaluation"): fixed seeded evaluation sets, the metrics
the navigation literature reports, and plots of learned paths beside A*'s. Used by every
learner, the evaluator service and bench/."""
