"""hybridneus.model."""
