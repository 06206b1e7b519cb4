"""mgelens workflow: mock or real imaging -> lens model -> isophotes -> sample summary.

Thin shim (docs/CONVENTIONS.md §0): the rules live in workflow/rules/*.smk; the default
target `rule all` must be defined here, because a rule from an included file never
becomes the default target. Run `snakemake -j2` from the repository root; choose another
sample with `--configfile config/slacs.yaml` (real SLACS lenses) or
`--configfile config/population.yaml` (38 mock lenses).
"""

from snakemake.utils import min_version

min_version("9.0")


configfile: f"{workflow.basedir}/config/config.yaml"


include: "workflow/rules/common.smk"
include: "workflow/rules/mocks.smk"
include: "workflow/rules/plots.smk"
include: "workflow/rules/analysis.smk"
include: "workflow/rules/slam.smk"


report: "workflow/report/workflow.rst"


rule all:
    input:
        all_targets(),
    default_target: True
