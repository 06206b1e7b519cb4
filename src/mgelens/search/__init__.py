"""Non-linear search: priors, parameter spaces, nested sampling and result files (SPEC §8)."""

from mgelens.search.model import (
    Parameter,
    ParameterSpace,
    axis_ratio_and_angle,
    derived_values,
    names_with_derived,
    shear_magnitude_and_angle,
)
from mgelens.search.priors import (
    Gaussian,
    LogUniform,
    Prior,
    TruncatedGaussian,
    Uniform,
    WidthModifier,
    passed_prior,
    prior_from_dict,
)
from mgelens.search.results import (
    PhaseResult,
    collect_versions,
    file_sha256,
    input_checksums,
    passed_priors,
)
from mgelens.search.sampler import (
    CheckpointMismatchError,
    SamplerOutput,
    SamplerSettings,
    credible_interval,
    pool_runs,
    run_nested,
    weighted_quantile,
)

__all__ = [
    "CheckpointMismatchError",
    "Gaussian",
    "LogUniform",
    "Parameter",
    "ParameterSpace",
    "PhaseResult",
    "Prior",
    "SamplerOutput",
    "SamplerSettings",
    "TruncatedGaussian",
    "Uniform",
    "WidthModifier",
    "axis_ratio_and_angle",
    "collect_versions",
    "credible_interval",
    "derived_values",
    "file_sha256",
    "input_checksums",
    "names_with_derived",
    "passed_prior",
    "passed_priors",
    "pool_runs",
    "prior_from_dict",
    "run_nested",
    "shear_magnitude_and_angle",
    "weighted_quantile",
]
