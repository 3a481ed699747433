"""sim_node package."""
