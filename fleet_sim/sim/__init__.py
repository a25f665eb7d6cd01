"""The SimPy simulation core: engine, demand, incidents, fleet commands, traffic, agents, motion."""
