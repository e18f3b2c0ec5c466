"""porecad: porous scaffolds and implicit vascular models as watertight, printable meshes."""

__version__ = "0.1.0"
