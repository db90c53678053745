"""The process half of navlearn: one folder per runtime role.

Each wires agents/, worlds/ and protocols/ to Zenoh, files and signals.
"""
