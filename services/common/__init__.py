"""What every service shares.

The Zenoh transport and its options, the process lifecycle, weights, the outbox.
"""
