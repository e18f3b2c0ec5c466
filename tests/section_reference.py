"""Reference sections of a mesh for the slicing tests (trimesh's section, even-odd by shapely): not porecad's."""

import functools


def section_area(mesh, z):
    """Area of a mesh's section at z (trimesh section, even-odd by shapely)."""
    from shapely.geometry import Polygon
    s = mesh.section(plane_origin=[0, 0, z], plane_normal=[0, 0, 1])
    if s is None:
        return 0.0
    polys = [Polygon(d[:, :2]).buffer(0) for d in s.discrete if len(d) >= 4]
    return functools.reduce(lambda a, b: a.symmetric_difference(b), polys).area if polys else 0.0
