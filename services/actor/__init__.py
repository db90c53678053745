"""The actor service.

Steps robots with the newest policy and publishes transition batches through its outbox.
"""
