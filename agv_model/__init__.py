"""agv_model: one AGV in detail (protocols, link timing, dynamics). Never imports fleet_sim."""
