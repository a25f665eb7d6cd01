"""The actors: the AGV (driving + state machine) and the fleet manager."""
