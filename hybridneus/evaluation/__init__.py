"""hybridneus.evaluation."""
