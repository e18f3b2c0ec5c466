"""Scalar fields (negative inside) and their algebra."""

from .base import Constant, Field, FunctionField, as_field
from .base import Intersection, Negate, Offset, Shell, Union
from .tpms import CATALOGUE, TPMSField, get_type, list_types

__all__ = ["Field", "FunctionField", "Constant", "as_field", "Union", "Intersection", "Negate",
           "Offset", "Shell", "TPMSField", "CATALOGUE", "get_type", "list_types"]
