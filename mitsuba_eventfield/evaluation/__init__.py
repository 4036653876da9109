"""Scoring against the renderer's ground truth: depth and reference views (``truth``), image quality
(``quality``), speed against accuracy (``bench``) and optics sweeps (``sweep``)."""
