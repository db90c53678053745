"""The evaluator service: measures each new policy version on held-out maps and reports it."""
