"""Medical images for patient-specific porous discs (000 ch.6).

* :mod:`.io` — volumes and multi-channel stacks (NIfTI, MHA/NRRD, DICOM
  series) with their geometry, checked for agreement;
* :mod:`.challenge` — the public IVD challenge layout (Dixon in-phase,
  opposed-phase, fat, water + labels);
* :mod:`.phantom` — a seeded multi-modal spine phantom;
* :mod:`.classical` — threshold / morphology / connected-component
  segmentation (discs in Dixon MR, bone in CT);
* :mod:`.metrics` — Dice/DOC, Hausdorff (max, 95th percentile), mean surface
  distance (000 §6.2.6).

Nothing here needs PyTorch; the U-Nets live in :mod:`porecad.seg`.
"""
