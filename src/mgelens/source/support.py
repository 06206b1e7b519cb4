"""Source support: the source pixels that the lensed arcs reach (issue #32).

The paper's source (SPEC §4) has a pixel wherever the traced mask lands. Outside the
Einstein ring the image plane is singly imaged, so there the source can copy any smooth
image-plane light, and on 3″ masks it takes a large share of the lens light's outer wings
(docs/recovery.md, "The source's support"). With a support, the source is zero outside the
region its arcs reach:

* the *arc pixels* are the image pixels where the adapt image Ξ (the lensed source of an
  earlier fit, SPEC §4.1) exceeds ``threshold`` times its maximum and, with a noise
  floor, also ``floor`` (k times the pixel's noise: arcs detected at k σ);
* the *support* is every source pixel that a traced sub-pixel of an arc pixel gives a
  non-zero interpolation weight (its natural neighbours, SPEC §4.4);
* the other source pixels leave the linear system: their fluxes are zero, their rows and
  columns of the mapping and of H are dropped (the prior of the kept pixels given zeros
  elsewhere), so ln det H and ln det(F + H) are those of the smaller system (SPEC §7).

The threshold is a hyper-parameter of the source, chosen by the evidence like the
regularization coefficients (``mesh.arc_threshold`` in SPix2).
"""

import numpy as np
from scipy import sparse


def arc_pixels(
    adapt_image: np.ndarray, threshold: float, floor: np.ndarray | None = None
) -> np.ndarray:
    """Bool (N_I,): slim image pixels whose adapt image exceeds ``threshold`` × its maximum
    and, if given, ``floor`` (N_I,), the same units as the adapt image (data units).

    Raises ``ValueError`` for a threshold outside (0, 1) or an adapt image without a
    positive pixel.
    """
    if not 0.0 < threshold < 1.0:
        raise ValueError(f"arc threshold must lie in (0, 1), got {threshold}")
    peak = float(np.max(adapt_image))
    if not peak > 0.0:
        raise ValueError("the adapt image has no positive pixel: no arcs to support a source")
    selected = adapt_image > threshold * peak
    if floor is not None:
        selected &= adapt_image > floor
    return selected


def reached_source_pixels(mapping: sparse.csr_matrix, image_pixels: np.ndarray) -> np.ndarray:
    """Bool (N_S,): source pixels with a non-zero mapping weight from ``image_pixels``.

    ``mapping`` is f (N_I × N_S, CSR) of :func:`mgelens.source.mapping.mapping_matrix`;
    ``image_pixels`` a bool (N_I,) selection of its rows.
    """
    rows = mapping[np.flatnonzero(image_pixels)]
    reached = np.zeros(mapping.shape[1], dtype=bool)
    reached[rows.indices[rows.data > 0.0]] = True
    return reached
