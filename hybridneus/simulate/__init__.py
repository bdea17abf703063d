"""hybridneus.simulate."""
