"""Studies over many runs: sweeps, fleet sizing, cross-checks."""
