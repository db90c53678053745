"""The learner service.

Inbox, fair queue, rate limiter, replay, NNQL/NIRL training, write-ahead log, checkpoints, status.
"""
