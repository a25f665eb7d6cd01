"""User-written files: layout, scenario, experiment, trace (validated models, loaders)."""
