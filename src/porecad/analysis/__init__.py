"""Analysis of meshes and scaffolds."""

from .basic import mesh_report

__all__ = ["mesh_report"]
