"""The ground floor under fleet_sim and agv_model: the files users write and read.

`checking` (StrictModel, validate, InputError: one way to check a user file, one message for
what is wrong with it), `reading` (text, YAML and JSON read safely) and `writing` (atomic writes
of every file the program leaves behind). It imports neither package.
"""
