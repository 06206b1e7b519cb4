"""Isophote analysis of each lens's fitted lens light and the sample summary (SPEC §9)."""


rule isophotes:
    input:
        unpack(isophote_inputs),
    output:
        image="results/{lens}/lens_light.fits",
        table="results/{lens}/isophotes.csv",
        summary="results/{lens}/isophotes.json",
        figure=report(
            "results/{lens}/figures/isophotes.png",
            caption="../report/isophotes.rst",
            category="Isophotes",
            labels={"lens": "{lens}"},
        ),
    log:
        "logs/{lens}/isophotes.log",
    benchmark:
        "results/{lens}/benchmarks/isophotes.tsv"
    params:
        mgelens_version=MGELENS_VERSION,
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens isophotes --phase results/{wildcards.lens}/mass --psf {input.psf:q} "
        "--save-image {output.image:q} --lens {wildcards.lens} --summary {output.summary:q} "
        "--figure {output.figure:q} --out {output.table:q} --threads {threads} > {log:q} 2>&1"


rule summary:
    input:
        isophote_summaries,
    output:
        table="results/summary/lenses.csv",
        figure=report(
            "results/summary/histograms.png",
            caption="../report/summary.rst",
            category="Sample",
        ),
    log:
        "logs/summary.log",
    benchmark:
        "results/summary/benchmarks/summary.tsv"
    params:
        mgelens_version=MGELENS_VERSION,
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens summary {input:q} --out-table {output.table:q} "
        "--out-figure {output.figure:q} > {log:q} 2>&1"


rule recovery:
    input:
        truth="results/{lens}/mock/truth.json",
        lens_light="results/{lens}/mock/lens_light_blurred.fits",
        lensed_source="results/{lens}/mock/lensed_source_blurred.fits",
        result="results/{lens}/mass/result.json",
        model="results/{lens}/mass/model.fits",
    output:
        "results/{lens}/recovery.json",
    wildcard_constraints:
        lens=MOCK_LENSES,
    log:
        "logs/{lens}/recovery.log",
    benchmark:
        "results/{lens}/benchmarks/recovery.tsv"
    params:
        mgelens_version=MGELENS_VERSION,
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens recovery --lens-dir results/{wildcards.lens}/mock "
        "--phase results/{wildcards.lens}/mass --out {output:q} --threads {threads} > {log:q} 2>&1"


rule recovery_table:
    input:
        recovery_records,
    output:
        "results/summary/recovery.csv",
    log:
        "logs/recovery_table.log",
    benchmark:
        "results/summary/benchmarks/recovery_table.tsv"
    params:
        mgelens_version=MGELENS_VERSION,
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens recovery --table {input:q} --out {output:q} > {log:q} 2>&1"
