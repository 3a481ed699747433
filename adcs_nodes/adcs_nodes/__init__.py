"""adcs_nodes package."""
