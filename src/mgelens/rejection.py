"""The value a likelihood returns for a sample that cannot be fitted (SPEC §8.4).

A degenerate source mesh, a non-positive-definite linear system or an NNLS iteration cap
rejects the sample instead of crashing the sampler. Kept in its own tiny module so that
samplers and result readers need not import the numerical core.
"""

REJECTED_LOG_LIKELIHOOD = -1e99
