"""fleet_sim: discrete-event AGV fleet throughput simulator for warehouse fleet sizing."""

__version__ = "0.1.0"
