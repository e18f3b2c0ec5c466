"""To the printer: slices straight from a design's field (or a mesh's sections), printability, build orientation.

See docs/printing.md. :func:`porecad.printing.slicing.slice_to` is the entry point.
"""

from .part import Part, from_source
from .profile import Printer, load_printer, printer_from_dict, printer_from_toml
from .slicing import slice_to

__all__ = ["Part", "Printer", "from_source", "load_printer", "printer_from_dict", "printer_from_toml",
           "slice_to"]
