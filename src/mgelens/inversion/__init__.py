"""Linear inversion: solves of the normal equations and Bayesian evidence terms (SPEC §6–7).

* :mod:`mgelens.inversion.solve` — unconstrained Cholesky solve ("pn-MGE"), and either solve
  with some unknowns forced to zero.
* :mod:`mgelens.inversion.nnls` — the fast non-negative least squares of Bro & De Jong on
  the normal equations ("nn-MGE").
* :mod:`mgelens.inversion.cholesky` — the checked Cholesky factorisations and solves both use.
* :mod:`mgelens.inversion.evidence` — log determinants and the log evidence.

Every linear-algebra failure raises :class:`mgelens.inversion.cholesky.InversionError`, which
a sampler turns into a rejected sample (SPEC §8.4).
"""
