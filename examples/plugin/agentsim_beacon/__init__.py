"""agentsim-beacon: the ``beacon`` scenario, its ``to_beacon`` policy and the ``beacon_ring`` release strategy."""
