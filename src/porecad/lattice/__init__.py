"""Lattice planning: a TPMS lattice in its domain (a box of cells, a disc, a body) made ready to mesh.

:mod:`.plan` turns a checked ``tpms``/``infill`` spec into a
:class:`~porecad.lattice.plan.LatticePlan` (the field, its grid, the body),
holds a porosity target on a body (calibration and its corrections) and
post-processes the mesh. The tpms and infill jobs, the slicer, the studio's
preview and the implicit 3MF export all plan a lattice through it; it sits
below :mod:`porecad.jobs` and imports nothing above it.
"""
