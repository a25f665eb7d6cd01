"""What an AGV is: states, the RSS-AGV-001 state machine, error codes, kinematics, battery,
records."""
