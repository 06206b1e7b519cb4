"""The SLaM chain of phases SP → SPix1 → SPix2 → LIGHT → MASS (SPEC §8).

* :mod:`~mgelens.pipeline.settings`: phase settings, the ``quick`` and ``paper`` profiles,
  YAML loading (``slam:`` section);
* :mod:`~mgelens.pipeline.models`: parameter spaces of the phases and the mapping of
  parameter values onto profiles;
* :mod:`~mgelens.pipeline.phases`: the phases as functions, file in → file out;
* :mod:`~mgelens.pipeline.records`: the maximum-likelihood model block of ``result.json``,
  its writer and its readers (the next phases, the analyses);
* :mod:`~mgelens.pipeline.products`: ``model.fits`` and the adapt image.
"""
