"""The demonstrator service: the A* expert or a human at the keyboard, publishing demonstrations."""
