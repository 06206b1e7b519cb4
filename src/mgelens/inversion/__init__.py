"""Linear inversion: solves of the normal equations and Bayesian evidence terms (SPEC §6–7).

* :mod:`mgelens.inversion.solve` — unconstrained Cholesky solve ("pn-MGE") and the fast
  non-negative least squares of Bro & De Jong on the normal equations ("nn-MGE").
* :mod:`mgelens.inversion.evidence` — log determinants and the log evidence.

Every linear-algebra failure raises :class:`mgelens.inversion.solve.InversionError`, which a
sampler turns into a rejected sample (SPEC §8.4).
"""
