"""Figures (matplotlib object-oriented API, no pyplot): functions return a
:class:`matplotlib.figure.Figure`; :func:`save_png` writes one atomically.

Images are shown with ``origin="lower"`` and an (x, y) arcsec extent, so +x is to the right
and +y up (SPEC §1.1).
"""

import os

from matplotlib.figure import Figure

from mgelens.atomic import atomic_path

DPI = 150


def save_png(figure: Figure, path: str | os.PathLike, dpi: int = DPI) -> None:
    """Write ``figure`` as a PNG to ``path`` (temporary name, then rename)."""
    with atomic_path(path) as temporary:
        figure.savefig(temporary, format="png", dpi=dpi)
