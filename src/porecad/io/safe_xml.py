"""XML from untrusted files (3MF models, VTK XML PolyData and UnstructuredGrid), parsed with bounds.

Parsing goes through `defusedxml <https://github.com/tiran/defusedxml>`_
with document type declarations forbidden, so no entity is ever expanded
(no "billion laughs", no external entities) and a DTD is refused as soon as
the parser meets it. On top of that the element nesting depth and the
number of elements are bounded while the events stream in, so a deeply
nested or endlessly repeated document is refused before a tree is built
(:data:`MAX_DEPTH`, :data:`MAX_ELEMENTS`).

Errors are :class:`~porecad.errors.InputError` in one line that names the
file and the position, never the document's text.
"""

from __future__ import annotations

import io
import os

from ..errors import InputError

__all__ = ["iterparse", "parse", "MAX_DEPTH", "MAX_ELEMENTS", "has_doctype"]

#: deepest element nesting accepted (3MF and VTK files nest fewer than 10 levels)
MAX_DEPTH = 64
#: most elements in one document (a 3MF of 50 million triangles has about 75 million)
MAX_ELEMENTS = 200_000_000


def _describe(exc) -> str:
    """A parser failure in words, without the document's text."""
    from defusedxml import DTDForbidden, EntitiesForbidden, ExternalReferenceForbidden
    if isinstance(exc, DTDForbidden):
        return "it declares a document type (DTD), which is not allowed"
    if isinstance(exc, EntitiesForbidden):
        return "it declares entities, which are not allowed"
    if isinstance(exc, ExternalReferenceForbidden):
        return "it refers to external resources, which is not allowed"
    pos = getattr(exc, "position", None)
    where = f" at line {pos[0]}, column {pos[1] + 1}" if pos else ""
    return f"malformed XML{where}"


def iterparse(source, what: str, events=("start", "end"), max_depth: int = MAX_DEPTH,
              max_elements: int = MAX_ELEMENTS):
    """Yield ``(event, element)`` like :func:`xml.etree.ElementTree.iterparse`, safely and bounded.

    Parameters
    ----------
    source : path, bytes or binary file object
        The document.
    what : str
        What the document is, for error messages (e.g. the file name).
    events : tuple of str
        Events wanted (``start`` is always tracked for the depth bound).
    max_depth, max_elements : int
        Bounds on nesting and element count.

    Raises
    ------
    InputError
        A DTD or entity declaration, malformed XML, nesting deeper than
        ``max_depth`` or more than ``max_elements`` elements.
    """
    from xml.etree.ElementTree import ParseError

    from defusedxml import DefusedXmlException
    from defusedxml.ElementTree import iterparse as defused_iterparse

    if isinstance(source, (bytes, bytearray, memoryview)):
        source = io.BytesIO(source)
    elif isinstance(source, (str, os.PathLike)):
        source = os.fspath(source)
    wanted = set(events)
    depth = 0
    count = 0
    try:
        for event, elem in defused_iterparse(source, events=("start", "end"), forbid_dtd=True):
            if event == "start":
                depth += 1
                count += 1
                if depth > max_depth:
                    raise InputError(f"{what}: XML elements nest more than {max_depth} levels deep")
                if count > max_elements:
                    raise InputError(f"{what}: more than {max_elements:,} XML elements")
            else:
                depth -= 1
            if event in wanted:
                yield event, elem
    except (ParseError, DefusedXmlException) as exc:
        raise InputError(f"{what}: not valid here: {_describe(exc)}") from None
    except (RecursionError, MemoryError):
        raise InputError(f"{what}: the XML is too deeply nested or too large") from None


def parse(source, what: str, max_depth: int = MAX_DEPTH, max_elements: int = MAX_ELEMENTS):
    """The root element of a document, parsed by :func:`iterparse` (bounded, no DTD)."""
    root = None
    for event, elem in iterparse(source, what, events=("start",), max_depth=max_depth,
                                 max_elements=max_elements):
        if root is None:
            root = elem
    if root is None:
        raise InputError(f"{what}: not valid here: an empty XML document")
    return root


def has_doctype(path, chunk: int = 1 << 20) -> bool:
    """Whether a file holds a document type or entity declaration (``<!DOCTYPE``, ``<!ENTITY``) anywhere.

    Used to refuse such files before handing them to a third-party XML
    reader (meshio's VTU and XDMF readers use :mod:`xml.etree`). The file is
    scanned in chunks (bounded memory).
    """
    marks = (b"<!DOCTYPE", b"<!ENTITY")
    tail = b""
    from .confine import regular_file
    regular_file(path, "an XML file")
    with open(path, "rb") as fh:
        while True:
            block = fh.read(chunk)
            if not block:
                return False
            window = tail + block
            if any(m in window for m in marks):
                return True
            tail = window[-16:]
