"""The SLaM chain (SPEC §8): SP -> SPix1 -> SPix2 -> LIGHT -> MASS, one rule per phase.

A phase reads only earlier phases' folders, so deleting one result reruns just that phase
(and those after it). Build a lens's chain with
`snakemake -j2 results/M1/mass/result.json`. One thread per phase, so that `-j2` fits two
lenses at a time; the config's `slam:` section goes to every phase (`--slam`) with only
that phase's sampler settings, and changing it reruns the phases. SPix1 also writes the
adapt image that SPix2, LIGHT and MASS read (rule `phase_spix1`).
"""

rule phase:
    input:
        unpack(phase_inputs),
    output:
        result="results/{lens}/{phase}/result.json",
        samples="results/{lens}/{phase}/samples.csv",
        model="results/{lens}/{phase}/model.fits",
    wildcard_constraints:
        phase="sp|spix2|light|mass",
    log:
        "logs/{lens}/{phase}.log",
    benchmark:
        "results/{lens}/benchmarks/{phase}.tsv"
    params:
        mgelens_version=MGELENS_VERSION,
        lens_dir=lens_imaging_folder,
        options=phase_options,
        slam=phase_settings,
    threads: 1
    priority: phase_priority
    resources:
        mem_mb=phase_mem_mb,
        runtime=600,
    retries: 1
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens phase {wildcards.phase} --lens-dir {params.lens_dir:q} "
        "--results results/{wildcards.lens} --threads {threads} {params.options} "
        "--slam {params.slam:q} "
        "> {log:q} 2>&1"


use rule phase as phase_spix1 with:
    output:
        result="results/{lens}/{phase}/result.json",
        samples="results/{lens}/{phase}/samples.csv",
        model="results/{lens}/{phase}/model.fits",
        adapt_image="results/{lens}/{phase}/adapt_image.fits",
    wildcard_constraints:
        phase="spix1",
