"""hybridneus.meshing."""
