"""Mock imaging (SPEC §10): one folder per mock lens, results/{lens}/mock/."""


rule simulate_mock:
    output:
        data="results/{lens}/mock/data.fits",
        noise_map="results/{lens}/mock/noise_map.fits",
        psf="results/{lens}/mock/psf.fits",
        model="results/{lens}/mock/model.fits",
        lens_light="results/{lens}/mock/lens_light.fits",
        lens_light_blurred="results/{lens}/mock/lens_light_blurred.fits",
        lensed_source="results/{lens}/mock/lensed_source.fits",
        lensed_source_blurred="results/{lens}/mock/lensed_source_blurred.fits",
        source="results/{lens}/mock/source.fits",
        truth="results/{lens}/mock/truth.json",
    log:
        "logs/{lens}/simulate_mock.log",
    benchmark:
        "results/{lens}/benchmarks/simulate_mock.tsv"
    wildcard_constraints:
        lens=MOCK_LENSES,
    params:
        mgelens_version=command_version("simulate"),
        recipe=simulate_recipe,
        folder=mock_folder,
        image_size=config["mock"]["image_size"],
        sub_size=config["mock"]["sub_size"],
    # one thread (a mock takes ~5 s) and before any phase: a two-thread job never fits
    # beside the one-thread phase jobs that keep the cores busy, so a lens's mock would
    # wait for other lenses' chains
    threads: 1
    priority: len(PHASES) + 1
    resources:
        mem_mb=simulate_mem_mb,
        runtime=10,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens simulate {params.recipe} --name {wildcards.lens} "
        "--image-size {params.image_size} --sub-size {params.sub_size} "
        "--threads {threads} --out {params.folder:q} > {log:q} 2>&1"
