"""File input and output: atomic writes and mesh file formats."""

from porecad.io.atomic import atomic_write, check_output_path
from porecad.io.meshfiles import read_mesh, write_mesh

__all__ = [
    "atomic_write",
    "check_output_path",
    "read_mesh",
    "write_mesh",
]
