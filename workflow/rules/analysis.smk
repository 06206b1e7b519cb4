"""Isophote analysis of each lens's fitted lens light (SPEC §9), its fit-quality flag
(mgelens.quality) and the sample summary with the comparison to published models."""


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
        mgelens_version=command_version("isophotes"),
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


rule fit_quality:
    input:
        unpack(quality_inputs),
    output:
        "results/{lens}/quality.json",
    log:
        "logs/{lens}/fit_quality.log",
    benchmark:
        "results/{lens}/benchmarks/fit_quality.tsv"
    params:
        mgelens_version=command_version("quality"),
        lens_dir=lens_imaging_folder,
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens quality --phase results/{wildcards.lens}/mass --lens-dir {params.lens_dir:q} "
        "--lens {wildcards.lens} --out {output:q} > {log:q} 2>&1"


rule summary:
    input:
        unpack(summary_inputs),
    output:
        table="results/summary/lenses.csv",
        figure=report(
            "results/summary/histograms.png",
            caption="../report/summary.rst",
            category="Sample",
        ),
        einstein=report(
            "results/summary/einstein_radii.png",
            caption="../report/einstein_radii.rst",
            category="Sample",
        ),
        mosaic=report(
            "results/summary/residual_mosaic.png",
            caption="../report/residual_mosaic.rst",
            category="Sample",
        ),
        slopes=report(
            "results/summary/slopes.png",
            caption="../report/slopes.rst",
            category="Sample",
        ),
        light_models="results/summary/light_models.csv",
    log:
        "logs/summary.log",
    benchmark:
        "results/summary/benchmarks/summary.tsv"
    params:
        mgelens_version=command_version("summary"),
        reference_dir=REFERENCE_DIR,
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens summary {input.summaries:q} --reference-dir {params.reference_dir:q} "
        "--out-table {output.table:q} --out-figure {output.figure:q} "
        "--out-einstein {output.einstein:q} --out-mosaic {output.mosaic:q} "
        "--out-slopes {output.slopes:q} --out-light-models {output.light_models:q} "
        "> {log:q} 2>&1"


rule recovery:
    input:
        truth="results/{lens}/mock/truth.json",
        lens_light="results/{lens}/mock/lens_light_blurred.fits",
        lensed_source="results/{lens}/mock/lensed_source_blurred.fits",
        result="results/{lens}/mass/result.json",
        model="results/{lens}/mass/model.fits",
        isophotes="results/{lens}/isophotes.csv",
    output:
        record="results/{lens}/recovery.json",
        figure=report(
            "results/{lens}/figures/isophote_recovery.png",
            caption="../report/isophote_recovery.rst",
            category="Mocks",
            subcategory="Isophote recovery",
            labels={"lens": "{lens}"},
        ),
    wildcard_constraints:
        lens=MOCK_LENSES,
    log:
        "logs/{lens}/recovery.log",
    benchmark:
        "results/{lens}/benchmarks/recovery.tsv"
    params:
        mgelens_version=command_version("recovery"),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens recovery --lens-dir results/{wildcards.lens}/mock "
        "--phase results/{wildcards.lens}/mass --isophotes {input.isophotes:q} "
        "--isophote-figure {output.figure:q} --out {output.record:q} --threads {threads} "
        "> {log:q} 2>&1"


rule recovery_table:
    input:
        recovery_records,
    output:
        table="results/summary/recovery.csv",
        targets="results/summary/recovery_targets.csv",
    log:
        "logs/recovery_table.log",
    benchmark:
        "results/summary/benchmarks/recovery_table.tsv"
    params:
        mgelens_version=command_version("recovery"),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens recovery --table {input:q} --out {output.table:q} "
        "--out-targets {output.targets:q} > {log:q} 2>&1"


rule coverage:
    input:
        records=recovery_records,
        quality=mock_quality_records,
    output:
        table="results/summary/coverage.csv",
        rows="results/summary/coverage_lenses.csv",
        targets="results/summary/coverage_targets.csv",
        figure=report(
            "results/summary/coverage.png",
            caption="../report/coverage.rst",
            category="Mocks",
        ),
    log:
        "logs/coverage.log",
    benchmark:
        "results/summary/benchmarks/coverage.tsv"
    params:
        mgelens_version=command_version("coverage"),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens coverage {input.records:q} --quality {input.quality:q} "
        "--out {output.table:q} --rows {output.rows:q} --targets {output.targets:q} "
        "--figure {output.figure:q} > {log:q} 2>&1"


rule chain_cost:
    input:
        chain_cost_inputs,
    output:
        table="results/summary/chain_cost.csv",
        figure=report(
            "results/summary/chain_cost.png",
            caption="../report/chain_cost.rst",
            category="Sample",
        ),
    log:
        "logs/chain_cost.log",
    benchmark:
        "results/summary/benchmarks/chain_cost.tsv"
    params:
        mgelens_version=command_version("cost"),
        cores=config["cost_cores"],
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens cost {input:q} --out {output.table:q} --figure {output.figure:q} "
        "--cores {params.cores} > {log:q} 2>&1"


rule smoothness:
    input:
        unpack(smoothness_inputs),
    output:
        figure=report(
            "results/summary/smoothness.png",
            caption="../report/smoothness.rst",
            category="Mocks",
        ),
        table="results/summary/smoothness.csv",
    log:
        "logs/smoothness.log",
    benchmark:
        "results/summary/benchmarks/smoothness.tsv"
    params:
        mgelens_version=command_version("smoothness"),
        folder=smoothness_folder,
        mask_radius=smoothness_mask_radius,
    threads: 1
    resources:
        mem_mb=1500,
        runtime=15,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens smoothness --lens-dir {params.folder:q} --mask-radius {params.mask_radius} "
        "--out {output.figure:q} --table {output.table:q} --threads {threads} > {log:q} 2>&1"


rule mock_study:
    input:
        mock_study_inputs,
    output:
        table="results/summary/mock_table.csv",
        markdown=report(
            "results/summary/mock_table.md",
            caption="../report/mock_table.rst",
            category="Mocks",
        ),
        annuli="results/summary/mock_light_annuli.csv",
        figures=[
            report(
                f"results/summary/lens_light_{model}.png",
                caption="../report/lens_light.rst",
                category="Mocks",
            )
            for model in PAPER_MOCK_MODELS
        ],
    log:
        "logs/mock_study.log",
    benchmark:
        "results/summary/benchmarks/mock_study.tsv"
    params:
        mgelens_version=command_version("mockstudy"),
        fits=mock_study_fits,
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens mockstudy {params.fits} --results results --out-table {output.table:q} "
        "--out-markdown {output.markdown:q} --out-annuli {output.annuli:q} "
        "--figures-dir results/summary > {log:q} 2>&1"
