"""Hand-made sampler runs for tests that need a posterior without sampling one."""

import numpy as np

from mgelens.search.posterior import SamplerOutput


def equal_weight_run(names, samples, log_likelihoods, settings=None, seed=0) -> SamplerOutput:
    """A converged dynesty-like run of equally weighted ``samples`` (n, n_free) with the
    given ln L, ln Z 0 ± 0.1, one call per sample."""
    n = len(samples)
    return SamplerOutput(
        names=tuple(names),
        samples=samples,
        log_weights=np.full(n, -np.log(n)),
        log_likelihoods=log_likelihoods,
        log_evidence=0.0,
        log_evidence_error=0.1,
        n_calls=n,
        n_rejected=0,
        runtime=1.0,
        n_resumes=0,
        method="dynesty_static",
        settings={} if settings is None else settings,
        seed=seed,
    )
