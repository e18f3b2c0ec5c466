"""Implicit vascular modelling (document 003): centreline graphs, skeleton marching,
localised segment fields, shape-preserving blends and thin layered walls."""
