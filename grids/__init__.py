"""Pure-PyTorch feature-grid encodings (installed as ``hybridneus.grids``)."""
