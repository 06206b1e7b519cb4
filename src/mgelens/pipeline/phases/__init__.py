"""The five SLaM phases (SPEC §8.1), one module each: its parameter space (``space``) and
the problem it samples (``problem(lens_dir, results_dir, settings, lens)``), read top to bottom.

* :mod:`~mgelens.pipeline.phases.sp`: lens light, SIE + shear and an MGE source;
* :mod:`~mgelens.pipeline.phases.spix1`: SIE + shear with a pixelized source;
* :mod:`~mgelens.pipeline.phases.spix2`: the source mesh and regularization;
* :mod:`~mgelens.pipeline.phases.light`: the lens light refitted;
* :mod:`~mgelens.pipeline.phases.mass`: EPL + shear, the result.

:func:`mgelens.pipeline.run.run_phase` runs one of them and writes its folder.
"""
