"""Names of the source-plane schemes a setting chooses between (no numerics here, so that
configuration can check a choice without loading the meshes)."""

INTERPOLATIONS = ("natural_neighbour", "nearest")
"""The source-plane interpolation schemes: natural-neighbour (Sibson) weights, or the
nearest mesh cell with weight 1 (SPEC §4.4)."""

EDGE_RULES = ("anchor", "continuous")
"""Treatments of the convex hull: the anchor's (discontinuous when a point joins or leaves
the hull) or the continuous one (:attr:`mgelens.source.mesh.VoronoiMesh.ringed`)."""

SIGNAL_AVERAGES = ("anchor", "weighted")
"""How a source pixel's signal averages the adapt image over the sub-pixels it serves
(:func:`mgelens.source.regularization.adaptive_pixel_signals`)."""

SIGNAL_MASSES = ("fitted", "spix2")
"""The mass through which a fixed source's adaptive signals are traced: each fitted mass's
own (anchor) or SPix2's, held (:attr:`mgelens.fit.PixelizedSource.signals_mass`)."""

KMEANS_SEEDINGS = ("kmeans++", "systematic")
"""Initial centres of the k-means source mesh: the anchor's k-means++ or the systematic
(stratified) draw along a Hilbert curve (:func:`mgelens.source.image_mesh.kmeans_centres`)."""
