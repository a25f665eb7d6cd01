"""The standards fleet_sim reads and writes: VDMA's Layout Interchange Format (LIF 1.0.0:
`lif`, `lif_export`, `lif_import`) and the VDA 5050 factsheet (`factsheet`, and the vehicle
profile made of one, `factsheet_profile`). They may use the rest of `fleet_sim.config`; the rest
never uses them (an import-linter contract holds it)."""
