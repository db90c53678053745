"""The processes: thin wiring of agents, worlds and protocols to Zenoh, files and signals."""
