"""Traffic control: the reservation table of node and corridor locks, routes, deadlocks."""
