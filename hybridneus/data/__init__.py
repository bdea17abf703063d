"""hybridneus.data."""
