"""The SLaM chain (SPEC §8): SP -> SPix1 -> SPix2 -> LIGHT -> MASS, one rule per phase.

A phase reads only earlier phases' folders, so deleting one result reruns just that phase
(and those after it). Build a lens's chain with
`snakemake -j2 results/M1/mass/result.json`. One thread per phase, so that `-j2` fits two
lenses at a time; the config's `slam:` section goes to every phase (`--slam`) with only
that phase's sampler settings, and changing it reruns the phases. SPix1 also writes the
adapt image that SPix2, LIGHT and MASS read (rule `phase_spix1`).

MASS: with several source meshes (`mass_meshes`, quick profile 2) each mesh is its own job
(rule `mass_mesh`, `mass_mesh<k>/`), so that the scheduler runs them side by side, and
rule `pool_mass` pools them into `mass/` (mgelens.pipeline.mesh_pool: the same files as
one job sampling the meshes in turn); with one mesh rule `phase` fits MASS.

SPix2: with one `source_pixels` count in the config, rule `phase` fits it. With a list,
each count is fitted into `spix2_n<count>/` (rule `spix2_candidate`) and rule
`choose_source_pixels` keeps the count SPix2's evidence prefers, copies it into `spix2/`,
which LIGHT and MASS read, and writes `source_pixels_choice.json`.

LIGHT: a lens whose sheet row pins `mge_sets` and `point_set` fits it once (rule
`phase_light`). A row with `auto` fits each candidate model into `light_<model>/` (rule
`light_candidate`); rule `choose_light` keeps the one the Bayesian evidence prefers,
copies it into `light/`, which MASS reads, and writes `model_choice.json`.
"""

rule phase:
    input:
        unpack(phase_inputs),
    output:
        result="results/{lens}/{phase}/result.json",
        samples="results/{lens}/{phase}/samples.csv",
        model="results/{lens}/{phase}/model.fits",
    wildcard_constraints:
        phase="|".join(
            ["sp", *([] if CHOSEN_PIXELS else ["spix2"]), *([] if MESH_JOBS else ["mass"])]
        ),
    log:
        "logs/{lens}/{phase}.log",
    benchmark:
        "results/{lens}/benchmarks/{phase}.tsv"
    params:
        mgelens_version=command_version("phase"),
        phase=phase_name,
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
        "mgelens phase {params.phase} --lens-dir {params.lens_dir:q} "
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


use rule phase as spix2_candidate with:
    wildcard_constraints:
        phase=SPIX2_FOLDERS if CHOSEN_PIXELS else "(?!)",


rule choose_source_pixels:
    input:
        spix2_candidate_results,
    output:
        result="results/{lens}/spix2/result.json",
        samples="results/{lens}/spix2/samples.csv",
        model="results/{lens}/spix2/model.fits",
        choice="results/{lens}/source_pixels_choice.json",
    wildcard_constraints:
        lens=".+" if CHOSEN_PIXELS else "(?!)",
    log:
        "logs/{lens}/choose_source_pixels.log",
    benchmark:
        "results/{lens}/benchmarks/choose_source_pixels.tsv"
    params:
        mgelens_version=command_version("choose"),
        counts=" ".join(str(n) for n in SOURCE_PIXELS),
        threshold=config["model_choice_threshold"],
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens choose --results results/{wildcards.lens} --source-pixels {params.counts} "
        "--threshold {params.threshold} --record {output.choice:q} > {log:q} 2>&1"


use rule phase as mass_mesh with:
    wildcard_constraints:
        phase=MESH_FOLDERS,


rule pool_mass:
    input:
        unpack(mesh_job_results),
    output:
        result="results/{lens}/mass/result.json",
        samples="results/{lens}/mass/samples.csv",
        model="results/{lens}/mass/model.fits",
    wildcard_constraints:
        lens=".+" if MESH_JOBS else "(?!)",
    log:
        f"logs/{{lens}}/{POOL_JOB}.log",
    benchmark:
        f"results/{{lens}}/benchmarks/{POOL_JOB}.tsv"
    params:
        mgelens_version=command_version("phase"),
        lens_dir=lens_imaging_folder,
        seed=config["sampler_seed"],
        slam=lambda wildcards: phase_settings(SimpleNamespace(lens=wildcards.lens, phase="mass")),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens phase mass --pool-meshes --lens-dir {params.lens_dir:q} "
        "--results results/{wildcards.lens} --seed {params.seed} --slam {params.slam:q} "
        "> {log:q} 2>&1"


use rule phase as phase_light with:
    wildcard_constraints:
        phase="light",
        lens=PINNED_LIGHT,


use rule phase as light_candidate with:
    wildcard_constraints:
        phase=LIGHT_FOLDERS,
        lens=CHOSEN_LIGHT,


rule choose_light:
    input:
        light_candidate_results,
    output:
        result="results/{lens}/light/result.json",
        samples="results/{lens}/light/samples.csv",
        model="results/{lens}/light/model.fits",
        choice="results/{lens}/model_choice.json",
    wildcard_constraints:
        lens=CHOSEN_LIGHT,
    log:
        "logs/{lens}/choose_light.log",
    benchmark:
        "results/{lens}/benchmarks/choose_light.tsv"
    params:
        mgelens_version=command_version("choose"),
        candidates=light_candidate_labels,
        threshold=config["model_choice_threshold"],
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "../envs/mgelens.yaml"
    shell:
        "mgelens choose --results results/{wildcards.lens} --candidates {params.candidates} "
        "--threshold {params.threshold} --record {output.choice:q} > {log:q} 2>&1"
