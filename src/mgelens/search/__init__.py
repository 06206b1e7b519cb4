"""Non-linear search: priors, parameter spaces, nested sampling and result files (SPEC §8)."""
