"""Bodies: closed meshes (and images) that scaffolds are built inside."""

from .load import load_body
from .mesh import MeshBody

__all__ = ["load_body", "MeshBody"]
