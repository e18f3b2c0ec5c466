"""Meshes: polygonisation, welding, capping, smoothing, decimation, validation."""

from .polygonise import Grid, PolygoniseResult, polygonise

__all__ = ["Grid", "PolygoniseResult", "polygonise"]
