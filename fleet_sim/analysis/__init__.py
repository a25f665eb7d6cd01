"""Run records -> KPIs, tables and statistics."""
