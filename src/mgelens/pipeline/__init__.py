"""The SLaM chain of phases SP → SPix1 → SPix2 → LIGHT → MASS (SPEC §8).

* :mod:`~mgelens.pipeline.settings`: phase settings, the ``quick`` and ``paper`` profiles,
  YAML loading (``slam:`` section);
* :mod:`~mgelens.pipeline.models`: parameter spaces of the phases and the mapping of
  parameter values onto profiles;
* :mod:`~mgelens.pipeline.phases`: one module per phase, its parameter space and problem;
* :mod:`~mgelens.pipeline.problem`: the imaging in the mask, the earlier phases read
  back, and the problem a phase samples;
* :mod:`~mgelens.pipeline.run`: running a phase (sampling, checkpoints, result files);
* :mod:`~mgelens.pipeline.records`: the maximum-likelihood model block of ``result.json``,
  its writer and its readers (the next phases, the analyses);
* :mod:`~mgelens.pipeline.products`: ``model.fits`` and the adapt image.
"""
