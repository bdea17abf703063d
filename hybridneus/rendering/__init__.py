"""hybridneus.rendering."""
