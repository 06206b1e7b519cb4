"""Figures per lens: the imaging preview, the overview of the final fit and its mass
posterior."""


rule preview:
    input:
        unpack(preview_inputs),
    output:
        report(
            "results/{lens}/figures/preview.png",
            caption="../report/preview.rst",
            category="Previews",
            labels={"lens": "{lens}"},
        ),
    log:
        "logs/{lens}/preview.log",
    benchmark:
        "results/{lens}/benchmarks/preview.tsv"
    params:
        mgelens_version=command_version("preview"),
        folder=lens_imaging_folder,
        pixel_scale=pixel_scale_option,
        contaminants=contaminants_option,
    threads: 1
    resources:
        mem_mb=preview_mem_mb,
        runtime=5,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens preview {params.folder:q} --out {output:q}{params.pixel_scale}{params.contaminants} "
        "--threads {threads} > {log:q} 2>&1"


rule overview:
    input:
        unpack(overview_inputs),
    output:
        report(
            "results/{lens}/figures/overview.png",
            caption="../report/overview.rst",
            category="Fits",
            labels={"lens": "{lens}"},
        ),
    log:
        "logs/{lens}/overview.log",
    benchmark:
        "results/{lens}/benchmarks/overview.tsv"
    params:
        mgelens_version=command_version("overview"),
        lens_dir=lens_imaging_folder,
    threads: 1
    resources:
        mem_mb=overview_mem_mb,
        runtime=15,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens overview --phase results/{wildcards.lens}/mass --lens-dir {params.lens_dir:q} "
        "--lens {wildcards.lens} --out {output:q} --threads {threads} > {log:q} 2>&1"


rule posterior:
    input:
        unpack(posterior_inputs),
    output:
        report(
            "results/{lens}/figures/posterior.png",
            caption="../report/posterior.rst",
            category="Posteriors",
            labels={"lens": "{lens}"},
        ),
    log:
        "logs/{lens}/posterior.log",
    benchmark:
        "results/{lens}/benchmarks/posterior.tsv"
    params:
        mgelens_version=command_version("posterior"),
        marks=posterior_marks,
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens posterior --phase results/{wildcards.lens}/mass --lens {wildcards.lens}"
        "{params.marks} --out {output:q} > {log:q} 2>&1"
