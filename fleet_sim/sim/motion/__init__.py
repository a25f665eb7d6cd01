"""Motion backends other than the closed form: SUMO through libsumo."""
