"""mgelens: strong-lens modelling with a Multi-Gaussian Expansion lens light.

Conventions (SPEC §1.1): coordinates (x, y) in arcsec, native arrays in FITS
orientation (row index increases with +y), angles in degrees counter-clockwise
from +x, ``ell_comps = (e1, e2) = (f cos 2φ, f sin 2φ)`` with f = (1 − q)/(1 + q).
"""

__version__ = "0.1.0"
CONVENTIONS_VERSION = "mgelens-conventions-1"
