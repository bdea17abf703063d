"""hybridneus.training."""
